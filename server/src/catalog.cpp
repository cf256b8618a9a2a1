#include "catalog.h"

#include <spdlog/spdlog.h>

#include <utility>

namespace gmr::server {

Catalog::Catalog(std::vector<LibraryEntry> library) { set_library(std::move(library)); }

void Catalog::set_library(std::vector<LibraryEntry> library) {
  library_ = std::move(library);
  by_name_.clear();
  for (std::size_t i = 0; i < library_.size(); ++i) by_name_.emplace(library_[i].name, i);
  compiled_forms_.clear();
}

void Catalog::reload(std::vector<LibraryEntry> library, StreamRegistry& streams) {
  LibraryChanges changes;
  std::map<std::string, std::pair<std::uint32_t, std::weak_ptr<const CompiledForm>>, std::less<>> before;
  for (std::size_t i = 0; i < library_.size(); ++i) {
    before[library_[i].name] = {library_[i].version,
                                i < compiled_forms_.size() ? compiled_forms_[i] : std::weak_ptr<const CompiledForm>()};
  }
  std::vector<std::weak_ptr<const CompiledForm>> forms(library.size());
  for (std::size_t i = 0; i < library.size(); ++i) {
    const auto it = before.find(library[i].name);
    if (it == before.end()) {
      ++changes.added;
      continue;
    }
    if (it->second.first == library[i].version) {
      forms[i] = it->second.second;
    } else {
      ++changes.changed;
    }
    before.erase(it);
  }
  changes.removed = before.size();
  set_library(std::move(library));
  compiled_forms_ = std::move(forms);
  const std::size_t ended = streams.end_where([this](const ViewContent& c) { return stale(c); });
  ++reloads_;
  changes_.added += changes.added;
  changes_.changed += changes.changed;
  changes_.removed += changes.removed;
  spdlog::info("library reloaded: {} motions, {} added, {} changed, {} removed; {} streams ended", library_.size(),
               changes.added, changes.changed, changes.removed, ended);
}

std::string Catalog::stale(const ViewContent& content) const {
  if (content.library_name.empty()) return {};
  const auto it = by_name_.find(content.library_name);
  if (it == by_name_.end()) {
    return "motion '" + content.library_name + "' was removed from the library";
  }
  const std::uint32_t now = library_[it->second].version;
  if (now == content.library_version) return {};
  return "motion '" + content.library_name + "' changed on disk (version " + std::to_string(content.library_version) +
         " -> " + std::to_string(now) + "): create a new view to see it";
}

Catalog::Found Catalog::find(std::string_view name) const {
  Found f;
  if (auto it = by_name_.find(name); it != by_name_.end()) {
    f.entry = &library_[it->second];
    f.index = it->second;
    return f;
  }
  f.live = live(name);
  return f;
}

std::shared_ptr<LiveSource> Catalog::live(std::string_view name) const {
  auto it = live_.find(name);
  return it == live_.end() || it->second->ended() ? nullptr : it->second;
}

double Catalog::metres_per_unit(const View& view) const {
  if (view.content()->metres_per_unit > 0.0) return view.content()->metres_per_unit;  // a rig's
  if (view.live()) {
    const auto source = view.live_source();
    return source ? source->metres_per_unit() : 0.0;
  }
  const auto it = by_name_.find(view.motion_name());
  return it == by_name_.end() ? 0.0 : library_[it->second].metres_per_unit;
}

std::uint64_t Catalog::owned_bytes(const View& view) const {
  if (view.live()) return 0;  // one frame, the size of a reply
  const Motion* own = &view.motion();
  if (auto it = by_name_.find(view.motion_name()); it != by_name_.end() && library_[it->second].motion.get() == own) {
    return 0;
  }
  // The copy (double) and, once a float32 stream uses it, its float form: the
  // values as floats and the one-frame kernel's frame-major copy of the angles.
  return own->values.size() * (sizeof(double) + 2 * sizeof(float));
}

std::shared_ptr<const CompiledForm> Catalog::compiled_form(std::size_t index) {
  if (compiled_forms_.size() != library_.size()) compiled_forms_.resize(library_.size());
  auto c = compiled_forms_[index].lock();
  if (!c) {
    c = std::make_shared<const CompiledForm>(library_[index].motion);
    compiled_forms_[index] = c;
  }
  return c;
}

bool Catalog::serves(std::string_view name) const { return by_name_.contains(name) || live_.contains(name); }

std::shared_ptr<LiveSource> Catalog::add_live(const std::string& name, Skeleton skeleton, double frame_time,
                                              double metres_per_unit) {
  auto source =
      std::make_shared<LiveSource>(name, next_live_serial_++, std::move(skeleton), frame_time, metres_per_unit);
  if (replay_work_) source->set_replay(*replay_work_, *replay_home_);
  source->count_replays(live_edit_replays_);
  live_[name] = source;
  return source;
}

void Catalog::remove_live(const std::shared_ptr<LiveSource>& source) {
  if (auto it = live_.find(source->name()); it != live_.end() && it->second == source) live_.erase(it);
}

std::vector<std::shared_ptr<LiveSource>> Catalog::local_sources() const {
  std::vector<std::shared_ptr<LiveSource>> out;
  for (const auto& [name, source] : live_) {
    if (source->origin().empty()) out.push_back(source);
  }
  return out;
}

void Catalog::count_live_frame(FrameFate fate) {
  switch (fate) {
    case FrameFate::kAccepted:
      ++live_frames_received_;
      break;
    case FrameFate::kRefused:
      ++live_frames_refused_;
      break;
    case FrameFate::kOverRate:
      ++live_frames_over_rate_;
      break;
  }
}

}  // namespace gmr::server
