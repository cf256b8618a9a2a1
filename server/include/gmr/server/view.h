// A view: one connection's own copy of a motion's root configuration, edited
// by shift/split/join/set-roots/strip-dummies, seen in world coordinates or
// from a joint (the intrinsic viewpoint). Its frames are computed by the
// library's view module (gmr/view/viewpoint.h): view_frame on the double
// path, FkFrameJob + view_frame_float on the float path.
#pragma once

#include <cstddef>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "gmr/core/error.h"
#include "gmr/motion/motion.h"

namespace gmr::fast {
class CompiledMotion;
}

namespace gmr::server {

class LiveSource;

// One structural edit of a view (shift, split, join, set roots, strip
// dummies), as a function of the motion it applies to: a live view replays
// its edits on every frame the source publishes.
using LiveStep = std::function<Result<Motion>(const Motion&)>;

// The float form of one motion (gmr::fast::CompiledMotion) for the fast
// path, compiled on first use and shared by every content showing that
// motion: the views of a library motion that no edit changed share one, an
// edit makes a new one. Compiling takes milliseconds and about as much memory
// as the motion's values, so only motions that a float32 stream plays pay it.
class CompiledForm {
 public:
  explicit CompiledForm(std::shared_ptr<const Motion> motion);
  ~CompiledForm();
  CompiledForm(const CompiledForm&) = delete;
  CompiledForm& operator=(const CompiledForm&) = delete;

  const std::shared_ptr<const Motion>& motion() const { return motion_; }
  // The compiled motion, or nullptr when it cannot be compiled (then the
  // double path serves; the reason is logged once). The first call compiles;
  // thread-safe.
  const fast::CompiledMotion* get() const;
  // fk_workspace_size() of the compiled motion (0 before get() or on failure).
  std::size_t workspace_floats() const { return workspace_floats_; }

 private:
  std::shared_ptr<const Motion> motion_;
  mutable std::once_flag once_;
  mutable std::unique_ptr<const fast::CompiledMotion> compiled_;
  mutable std::size_t workspace_floats_ = 0;
};

// What a frame of a view is computed from; immutable once built, shared by
// the streams that send it.
struct ViewContent {
  std::shared_ptr<const Motion> motion;  // pre-rotation
  int relative_to = -1;                  // joint index of the viewer; -1: world
  std::uint32_t skeleton_version = 1;
  // The float form of `motion` (same motion), for float32 streams; null: none
  // (the double path serves).
  std::shared_ptr<const CompiledForm> compiled;
  // A view of a live source: the edits made since the source's skeleton, in
  // order, and `motion` is one frame (the newest when the view last changed).
  // Null for library motions.
  std::shared_ptr<const std::vector<LiveStep>> live_steps;
  // Those edits spelled out (streams/live_key.h) and digested (SHA-256 of
  // the previous edits' digest and this edit's key), and a hash of it: views
  // of one source with equal keys make equal frames, so the source replays
  // the edits once for all of them. Null with no edits.
  std::shared_ptr<const std::string> live_key;
  std::size_t live_key_hash = 0;
  // The library motion it shows, and which version of it (LibraryEntry::
  // version): a reload that changes or removes it ends its streams
  // (Catalog::stale). Empty for live sources.
  std::string library_name;
  std::uint32_t library_version = 0;
  // The unit of `motion` in metres when an edit changed it (a retarget onto a
  // rig that states its unit); 0: the source's.
  double metres_per_unit = 0.0;
};

// What an edit reports besides the view it makes.
struct EditReport {
  double offset_spread = 0.0;        // join: how far the joined root's offset varies
  std::vector<std::string> removed;  // strip dummies: the joints it removed
};

// One structural edit of a view, taken apart so that the server computes it
// off its I/O thread: made and checked against the view (View::edit_*),
// run anywhere (run() reads only immutable data), then committed on the
// view's own thread (View::commit).
class ViewEdit {
 public:
  // The view's next content, or why the edit fails. Thread-safe; may take
  // long on a long motion. With `compile`, the float form is compiled here too.
  Result<std::shared_ptr<const ViewContent>> run() const;
  // The content the edit applies to.
  const std::shared_ptr<const ViewContent>& base() const { return base_; }
  // Values (frames x channels) it reads: what it costs.
  std::size_t values() const { return base_->motion->values.size(); }
  // At most the values it writes, known before anything is computed: every
  // frame, every joint with all six channels (no edit gives a joint more).
  // A channel-less motion of 2^20 frames reads nothing and may write much.
  // A retarget writes the rig's joints, however many the view has.
  std::uint64_t values_bound() const {
    const Motion& m = *base_->motion;
    const std::uint64_t joints = std::max<std::uint64_t>(m.skeleton.size(), written_joints_);
    return static_cast<std::uint64_t>(m.frame_count) * std::max<std::uint64_t>(m.stride(), 6 * joints);
  }
  // What the last run() reported.
  const EditReport& report() const { return *report_; }

  bool compile = false;  // float32 streams play the view: compile its float form in run()

 private:
  friend class View;
  ViewEdit(std::string what, std::string key, LiveStep step, std::shared_ptr<const ViewContent> base,
           std::shared_ptr<EditReport> report);

  std::string what_;
  std::string key_;  // the step spelled out (ViewContent::live_key)
  LiveStep step_;
  std::size_t written_joints_ = 0;  // joints of the motion it makes, when that may be more than the view's
  double metres_per_unit_ = 0.0;    // the unit of the motion it makes, when it changes it (a retarget)
  std::shared_ptr<const ViewContent> base_;
  std::shared_ptr<EditReport> report_;
};

class View {
 public:
  // `compiled`: the float form of `motion` to share (e.g. with other views of
  // the same library motion); null: the view makes its own, compiled on first use.
  // `library_version`: which version of library motion `motion_name` it is.
  View(std::uint32_t id, std::string motion_name, std::shared_ptr<const Motion> motion,
       std::shared_ptr<const CompiledForm> compiled = {}, std::uint32_t library_version = 1);
  // A view of live source `source` named `motion_name`, starting from its
  // newest frame `newest` (a one-frame motion).
  View(std::uint32_t id, std::string motion_name, std::shared_ptr<const Motion> newest,
       std::weak_ptr<LiveSource> source);

  std::uint32_t id() const { return id_; }
  const std::string& motion_name() const { return motion_name_; }
  const std::shared_ptr<const ViewContent>& content() const { return content_; }
  // Puts back a content this view had (an edit the server then refused).
  void restore(std::shared_ptr<const ViewContent> content) { content_ = std::move(content); }
  const Motion& motion() const { return *content_->motion; }
  // The live source this view shows (null for a library motion, or once the
  // source is gone).
  std::shared_ptr<LiveSource> live_source() const { return live_.lock(); }
  bool live() const { return content_->live_steps != nullptr; }

  // The structural edits, made and checked against the view now (an unknown
  // joint fails here, with ErrorKind::kNotFound), computed by run(), and
  // installed by commit(). Joints by name; errors name the joint and the reason.
  Result<ViewEdit> edit_shift_root(const std::string& joint) const;
  Result<ViewEdit> edit_split(const std::string& joint) const;
  Result<ViewEdit> edit_join(const std::string& root) const;
  Result<ViewEdit> edit_set_roots(const std::vector<std::string>& roots) const;
  Result<ViewEdit> edit_strip_dummies() const;
  // Onto another humanoid skeleton (gmr/retarget/retarget.h): `rig` holds the
  // rig's skeleton and, as its one frame when it has one, the pose it stands
  // in. Checked here (maps, roles, a world viewpoint); run() retargets every
  // frame, and a live view replays it on each frame. `rig_metres_per_unit`:
  // the rig's unit, the view's after it (0: the rig is in the source's unit).
  Result<ViewEdit> edit_retarget(std::shared_ptr<const Motion> rig, std::map<std::string, std::string> target_map,
                                 std::map<std::string, std::string> source_map, double rig_metres_per_unit = 0.0) const;
  // Installs what `edit.run()` gave, bumping skeleton_version when the
  // structure changed; fails, leaving the view as it is, when the view
  // changed since the edit was made.
  Status commit(const ViewEdit& edit, std::shared_ptr<const ViewContent> next);

  // The same edits at once: each either applies, or fails and leaves the
  // view as it was.
  Status shift_root(const std::string& joint) { return apply(edit_shift_root(joint)); }
  Status split(const std::string& joint) { return apply(edit_split(joint)); }
  Status join(const std::string& root, double* out_offset_spread = nullptr);
  Status set_roots(const std::vector<std::string>& roots) { return apply(edit_set_roots(roots)); }
  Status strip_dummies(std::vector<std::string>* out_removed = nullptr);
  Status set_relative_to(const std::string& joint);  // empty: world coordinates (cheap: never a ViewEdit)

  // The joint's index, or an error (ErrorKind::kNotFound) "view 3 (walk) has
  // no joint 'x'". Every edit fails with that error for an unknown joint.
  Result<int> joint_index(const std::string& name) const;

 private:
  void replace(std::shared_ptr<const Motion> motion, int relative_to, std::shared_ptr<const CompiledForm> compiled = {},
               std::shared_ptr<const std::vector<LiveStep>> live_steps = {});
  // Runs and commits `edit`.
  Status apply(const Result<ViewEdit>& edit);
  // An edit applying `step` to the view's motion (`what` prefixes its error).
  // `key` spells out what `step` does to a frame (streams/live_key.h).
  ViewEdit make_edit(std::string what, std::string key, LiveStep step, std::shared_ptr<EditReport> report = {}) const;

  std::uint32_t id_;
  std::string motion_name_;
  std::shared_ptr<const ViewContent> content_;
  std::weak_ptr<LiveSource> live_;
};

}  // namespace gmr::server
