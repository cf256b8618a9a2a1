#include "gmr/server/view.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <exception>
#include <functional>
#include <mutex>
#include <new>
#include <optional>

#include "gmr/fast/compiled_motion.h"
#include "gmr/fast/fast_fk.h"
#include "gmr/ops/convert.h"
#include "gmr/ops/join_tree.h"
#include "gmr/ops/set_roots.h"
#include "gmr/ops/shift_root.h"
#include "gmr/ops/split_tree.h"
#include "gmr/ops/strip_dummies.h"
#include "gmr/retarget/retarget.h"
#include "live_key.h"
#include "transport/digest.h"

namespace gmr::server {

CompiledForm::CompiledForm(std::shared_ptr<const Motion> motion) : motion_(std::move(motion)) {}
CompiledForm::~CompiledForm() = default;

const fast::CompiledMotion* CompiledForm::get() const {
  std::call_once(once_, [this] {
    if (!motion_) return;
    const auto joints = motion_->skeleton.size();
    const auto frames = motion_->frame_count;
    try {
      auto c = fast::CompiledMotion::compile(*motion_);
      if (!c.ok()) {
        spdlog::warn("float32 streams of a motion ({} joints, {} frames) use the double path: {}", joints, frames,
                     c.error().to_string());
        return;
      }
      if (c->joint_count() != joints || c->frame_count() != frames) {
        spdlog::warn(
            "float32 streams of a motion ({} joints, {} frames) use the double path: "
            "its compiled form has {} joints, {} frames",
            joints, frames, c->joint_count(), c->frame_count());
        return;
      }
      auto owned = std::make_unique<const fast::CompiledMotion>(std::move(c).value());
      workspace_floats_ = fast::fk_workspace_size(*owned);
      compiled_ = std::move(owned);
    } catch (const std::exception& e) {  // std::bad_alloc for an absurdly large motion
      spdlog::warn("float32 streams of a motion ({} joints, {} frames) use the double path: compiling failed: {}",
                   joints, frames, e.what());
      compiled_.reset();
      workspace_floats_ = 0;
    }
  });
  return compiled_.get();
}

View::View(std::uint32_t id, std::string motion_name, std::shared_ptr<const Motion> newest,
           std::weak_ptr<LiveSource> source)
    : id_(id), motion_name_(std::move(motion_name)), live_(std::move(source)) {
  auto c = std::make_shared<ViewContent>();
  c->motion = std::move(newest);
  c->live_steps = std::make_shared<const std::vector<LiveStep>>();
  content_ = std::move(c);
}

View::View(std::uint32_t id, std::string motion_name, std::shared_ptr<const Motion> motion,
           std::shared_ptr<const CompiledForm> compiled, std::uint32_t library_version)
    : id_(id), motion_name_(std::move(motion_name)) {
  auto c = std::make_shared<ViewContent>();
  if (!compiled || compiled->motion() != motion) compiled = std::make_shared<const CompiledForm>(motion);
  c->motion = std::move(motion);
  c->compiled = std::move(compiled);
  c->library_name = motion_name_;
  c->library_version = library_version;
  content_ = std::move(c);
}

Result<int> View::joint_index(const std::string& name) const {
  const int j = motion().skeleton.find(name);
  if (j < 0) {
    return make_error(ErrorKind::kNotFound,
                      "view " + std::to_string(id_) + " (" + motion_name_ + ") has no joint '" + name + "'");
  }
  return j;
}

namespace {

// The same joints (names, in the same order) with the same parents and soft
// links: what a client's joint indices and skeleton mean.
bool same_structure(const Skeleton& a, const Skeleton& b) {
  if (a.size() != b.size()) return false;
  for (int j = 0; j < static_cast<int>(a.size()); ++j) {
    const Joint& x = a.joint(j);
    const Joint& y = b.joint(j);
    if (x.name != y.name || x.parent != y.parent || x.soft_parent != y.soft_parent) return false;
  }
  return true;
}

}  // namespace

namespace {

// The content after `base` with this motion and viewer: a new float form
// unless the motion is the same (a live view's one-frame motion gets none:
// its streams compute it on the double path). The version moves only when
// what a client sees changes: the joints, their order and links, or the frame
// the coordinates are in. An edit that gives the same structure (a shift to
// the root it has, stripping a motion with no zero-length bone) keeps it.
std::shared_ptr<ViewContent> next_content(const ViewContent& base, std::shared_ptr<const Motion> motion,
                                          int relative_to, std::shared_ptr<const CompiledForm> compiled,
                                          std::shared_ptr<const std::vector<LiveStep>> live_steps) {
  auto c = std::make_shared<ViewContent>();
  if (!live_steps && (!compiled || compiled->motion() != motion)) {
    compiled = std::make_shared<const CompiledForm>(motion);
  }
  const bool same = relative_to == base.relative_to && same_structure(motion->skeleton, base.motion->skeleton);
  c->motion = std::move(motion);
  c->compiled = live_steps ? nullptr : std::move(compiled);
  c->relative_to = relative_to;
  c->skeleton_version = base.skeleton_version + (same ? 0 : 1);
  if (live_steps == base.live_steps) {
    c->live_key = base.live_key;
    c->live_key_hash = base.live_key_hash;
  }
  c->live_steps = std::move(live_steps);
  c->library_name = base.library_name;
  c->library_version = base.library_version;
  c->metres_per_unit = base.metres_per_unit;
  return c;
}

// A step's joint, by name in the motion it is applied to (a live view's
// frames all have the structure the edit was made on).
Result<int> find_joint(const Motion& m, const std::string& name) {
  const int j = m.skeleton.find(name);
  if (j < 0) return make_error(ErrorKind::kNotFound, "no joint '" + name + "'");
  return j;
}

}  // namespace

void View::replace(std::shared_ptr<const Motion> motion, int relative_to, std::shared_ptr<const CompiledForm> compiled,
                   std::shared_ptr<const std::vector<LiveStep>> live_steps) {
  content_ = next_content(*content_, std::move(motion), relative_to, std::move(compiled), std::move(live_steps));
}

ViewEdit::ViewEdit(std::string what, std::string key, LiveStep step, std::shared_ptr<const ViewContent> base,
                   std::shared_ptr<EditReport> report)
    : what_(std::move(what)),
      key_(std::move(key)),
      step_(std::move(step)),
      base_(std::move(base)),
      report_(std::move(report)) {
  if (!report_) report_ = std::make_shared<EditReport>();
}

Result<std::shared_ptr<const ViewContent>> ViewEdit::run() const {
  const ViewContent& base = *base_;
  auto result = step_(*base.motion);
  if (!result.ok()) return make_error(result.error().kind, what_ + ": " + result.error().to_string());
  auto next = std::make_shared<const Motion>(std::move(result).value());
  // The viewer joint stays the same joint, by name.
  int viewer = -1;
  if (base.relative_to >= 0) {
    const std::string& name = base.motion->skeleton.joint(base.relative_to).name;
    viewer = next->skeleton.find(name);
    if (viewer < 0) return make_error(what_ + ": it would remove the viewer joint '" + name + "'");
  }
  // A live view remembers the step, to replay it on every frame.
  std::shared_ptr<const std::vector<LiveStep>> steps;
  if (base.live_steps) {
    auto more = std::make_shared<std::vector<LiveStep>>(*base.live_steps);
    more->push_back(step_);
    steps = std::move(more);
  }
  auto content = next_content(base, std::move(next), viewer, {}, std::move(steps));
  if (content->live_steps) {
    // A digest, not the text: a retarget's key holds the rig's and the
    // source's joints, and LiveSource compares keys per stream and frame.
    const auto digest = sha256(base.live_key ? *base.live_key + key_ : key_);
    auto key = std::make_shared<const std::string>(digest.begin(), digest.end());
    content->live_key_hash = std::hash<std::string>{}(*key);
    content->live_key = std::move(key);
  }
  if (metres_per_unit_ > 0.0) content->metres_per_unit = metres_per_unit_;
  if (compile && content->compiled) content->compiled->get();
  return std::shared_ptr<const ViewContent>(std::move(content));
}

ViewEdit View::make_edit(std::string what, std::string key, LiveStep step, std::shared_ptr<EditReport> report) const {
  ViewEdit edit(std::move(what), std::move(key), std::move(step), content_, std::move(report));
  // Float32 streams played the view: its new float form is compiled with the
  // edit, not on the I/O thread at their next frame.
  edit.compile = content_->compiled && content_->compiled->workspace_floats() > 0;
  return edit;
}

Status View::commit(const ViewEdit& edit, std::shared_ptr<const ViewContent> next) {
  if (edit.base() != content_) {
    return make_error(ErrorKind::kFailedPrecondition,
                      "view " + std::to_string(id_) + " changed while the edit was computed; make it again");
  }
  content_ = std::move(next);
  return Ok{};
}

Status View::apply(const Result<ViewEdit>& edit) {
  if (!edit.ok()) return edit.error();
  auto next = edit->run();
  if (!next.ok()) return next.error();
  return commit(*edit, std::move(next).value());
}

Result<ViewEdit> View::edit_shift_root(const std::string& joint) const {
  if (auto j = joint_index(joint); !j.ok()) return j.error();
  return make_edit("shift root to '" + joint + "'", LiveKey("shift root").put(joint).take(),
                   [joint](const Motion& m) -> Result<Motion> {
                     auto j = find_joint(m, joint);
                     if (!j.ok()) return j.error();
                     return gmr::shift_root(m, *j);
                   });
}

Result<ViewEdit> View::edit_split(const std::string& joint) const {
  auto j = joint_index(joint);
  if (!j.ok()) return j.error();
  if (motion().skeleton.is_root(*j)) return make_error("split at '" + joint + "': it is already a root");
  return make_edit("split at '" + joint + "'", LiveKey("split").put(joint).take(),
                   [joint](const Motion& m) -> Result<Motion> {
                     auto at = find_joint(m, joint);
                     if (!at.ok()) return at.error();
                     return split_tree(m, *at);
                   });
}

Result<ViewEdit> View::edit_join(const std::string& root) const {
  if (auto j = joint_index(root); !j.ok()) return j.error();
  // The report of the last application: this edit's, read after run().
  auto report = std::make_shared<EditReport>();
  return make_edit(
      "join '" + root + "'", LiveKey("join").put(root).take(),
      [root, report](const Motion& m) -> Result<Motion> {
        auto j = find_joint(m, root);
        if (!j.ok()) return j.error();
        JoinReport r;
        auto joined = join_tree(m, *j, &r);
        report->offset_spread = r.offset_spread;
        return joined;
      },
      report);
}

Result<ViewEdit> View::edit_retarget(std::shared_ptr<const Motion> rig, std::map<std::string, std::string> target_map,
                                     std::map<std::string, std::string> source_map, double rig_metres_per_unit) const {
  if (content_->relative_to >= 0) {
    return make_error("retarget: the view is seen from '" + motion().skeleton.joint(content_->relative_to).name +
                      "'; set world coordinates first, and a viewpoint on the rig's joints after");
  }
  // The maps live as long as the step (RetargetOptions points into them).
  struct Maps {
    std::map<std::string, std::string> target, source;
    RetargetOptions options() const {
      RetargetOptions o;
      if (!target.empty()) o.target_map = &target;
      if (!source.empty()) o.source_map = &source;
      return o;
    }
  };
  auto maps = std::make_shared<const Maps>(Maps{std::move(target_map), std::move(source_map)});
  const RetargetOptions options = maps->options();
  auto first = Retargeter::make(motion(), *rig, options);
  if (!first.ok()) return first.error();
  // The plan is made once: a live view replays this step on every frame, each
  // a one-frame motion on the same skeleton (a re-rooted view makes another).
  struct Plan {
    Retargeter retargeter;
    std::shared_ptr<const std::optional<PreRotationGather>> gather;  // made on the first frame
  };
  struct Cache {
    std::mutex mutex;
    Plan plan;
  };
  auto cache = std::make_shared<Cache>();
  cache->plan.retargeter = std::move(first).value();
  // The plan depends on the rig, the maps and the view's motion (its first
  // frame too, when that is the source's reference pose).
  LiveKey key("retarget");
  key.put_motion(*rig, true).put_motion(motion(), cache->plan.retargeter.plan().source_reference != "rest pose");
  for (const auto* map : {&maps->target, &maps->source}) {
    key.put_number(static_cast<double>(map->size()));
    for (const auto& [role, joint] : *map) key.put(role).put(joint);
  }
  ViewEdit edit = make_edit("retarget", key.take(), [rig, maps, cache](const Motion& m) -> Result<Motion> {
    Plan p;
    {
      std::lock_guard lock(cache->mutex);
      p = cache->plan;
    }
    if (!p.retargeter.fits(m)) {
      auto made = Retargeter::make(m, *rig, maps->options());
      if (!made.ok()) return made.error();
      p = Plan{std::move(made).value(), nullptr};
    }
    if (!p.gather) {
      p.gather = std::make_shared<const std::optional<PreRotationGather>>(
          PreRotationGather::make(p.retargeter.output_skeleton()));
      std::lock_guard lock(cache->mutex);
      cache->plan = p;
    }
    if (!*p.gather) {
      auto out = p.retargeter.apply(m);
      if (!out.ok()) return out.error();
      return to_pre_rotation(*out);
    }
    auto values = p.retargeter.apply_values(m);
    if (!values.ok()) return values.error();
    return (*p.gather)->apply(*values, m.frame_count, m.frame_time);
  });
  edit.written_joints_ = rig->skeleton.size();
  edit.metres_per_unit_ = rig_metres_per_unit;
  return edit;
}

Result<ViewEdit> View::edit_set_roots(const std::vector<std::string>& roots) const {
  if (roots.empty()) return make_error("set roots: give at least one root");
  for (const auto& r : roots) {
    if (auto j = joint_index(r); !j.ok()) return j.error();
  }
  LiveKey key("set roots");
  for (const auto& r : roots) key.put(r);
  return make_edit("set roots", key.take(), [roots](const Motion& m) -> Result<Motion> {
    std::vector<int> idx;
    for (const auto& r : roots) {
      auto j = find_joint(m, r);
      if (!j.ok()) return j.error();
      idx.push_back(*j);
    }
    return gmr::set_roots(m, idx);
  });
}

Result<ViewEdit> View::edit_strip_dummies() const {
  auto report = std::make_shared<EditReport>();
  return make_edit(
      "strip dummies", LiveKey("strip dummies").take(),
      [report](const Motion& m) -> Result<Motion> {
        std::vector<RemovedJoint> removed;
        auto stripped = gmr::strip_dummies(m, &removed);
        report->removed.clear();
        for (const auto& r : removed) report->removed.push_back(r.name);
        return stripped;
      },
      report);
}

Status View::join(const std::string& root, double* out_offset_spread) {
  auto edit = edit_join(root);
  Status s = apply(edit);
  if (s.ok() && out_offset_spread) *out_offset_spread = edit->report().offset_spread;
  return s;
}

Status View::strip_dummies(std::vector<std::string>* out_removed) {
  auto edit = edit_strip_dummies();
  Status s = apply(edit);
  if (s.ok() && out_removed) *out_removed = edit->report().removed;
  return s;
}

Status View::set_relative_to(const std::string& joint) {
  int viewer = -1;
  if (!joint.empty()) {
    auto j = joint_index(joint);
    if (!j.ok()) return j.error();
    viewer = *j;
  }
  replace(content_->motion, viewer, content_->compiled, content_->live_steps);  // same motion: same float form
  return Ok{};
}

}  // namespace gmr::server
