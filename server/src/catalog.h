// Catalog: every motion the server serves, by name: the library's, and the
// live sources being published here or on other replicas. "Is this name a
// library motion or a live source?" is answered here alone, and the by-name
// index is built here alone. Also the float forms that unedited views of a
// library motion share. On the control loop.
#pragma once

#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "gmr/markers/marker_frames.h"
#include "gmr/server/library.h"
#include "gmr/server/view.h"
#include "live/live_directory.h"
#include "live/live_source.h"
#include "streams/stream_registry.h"

namespace gmr::server {

class Catalog final : public LiveDirectory {
 public:
  explicit Catalog(std::vector<LibraryEntry> library = {});

  // Replaces the library (a server made without one gets it later).
  void set_library(std::vector<LibraryEntry> library);
  // Replaces the library with a reloaded one (reload_library): entries with
  // the same name and version are the same motion (their shared float forms
  // stay); the streams of views of a motion that changed or left end with
  // the reason (stale), and the changes are counted and logged.
  void reload(std::vector<LibraryEntry> library, StreamRegistry& streams);
  std::uint64_t reloads() const { return reloads_; }
  const LibraryChanges& library_changes() const { return changes_; }
  // Why `content`, a view's, no longer shows what the library serves under
  // its name (its motion changed on disk or was removed); empty when it does,
  // and for live views.
  std::string stale(const ViewContent& content) const;
  const std::vector<LibraryEntry>& library() const { return library_; }

  // What a name is: a library motion (`entry`, at `index`), a live source
  // that has not ended (`live`), or nothing (both null).
  struct Found {
    const LibraryEntry* entry = nullptr;
    std::size_t index = 0;
    std::shared_ptr<LiveSource> live;
    explicit operator bool() const { return entry != nullptr || live != nullptr; }
  };
  Found find(std::string_view name) const;
  // The live source named `name` that has not ended, or null.
  std::shared_ptr<LiveSource> live(std::string_view name) const;
  // Every live source listed, by name.
  const std::map<std::string, std::shared_ptr<LiveSource>, std::less<>>& live_sources() const { return live_; }

  // The unit of the motion a view shows (0: unknown): the library's word, or
  // the live source's.
  double metres_per_unit(const View& view) const;
  // Bytes of motion `view` owns beyond the library's (an edited copy, and
  // the float form a float32 stream makes of it); a live view owns none.
  std::uint64_t owned_bytes(const View& view) const;
  // The float form unedited views of library entry `index` share (made when
  // no view holds one: memory follows what is being streamed).
  std::shared_ptr<const CompiledForm> compiled_form(std::size_t index);

  // Where live sources replay their views' edits, and where the frames
  // return (LiveSource::set_replay); not set: inline.
  void set_replay(net::any_io_executor work, net::any_io_executor home) {
    replay_work_ = std::move(work);
    replay_home_ = std::move(home);
  }

  // LiveDirectory.
  bool serves(std::string_view name) const override;
  std::shared_ptr<LiveSource> add_live(const std::string& name, Skeleton skeleton, double frame_time,
                                       double metres_per_unit) override;
  void remove_live(const std::shared_ptr<LiveSource>& source) override;
  std::vector<std::shared_ptr<LiveSource>> local_sources() const override;
  void count_live_frame(FrameFate fate) override;

  std::uint64_t live_frames_received() const { return live_frames_received_; }
  std::uint64_t live_frames_refused() const { return live_frames_refused_; }
  std::uint64_t live_frames_over_rate() const { return live_frames_over_rate_; }
  std::uint64_t live_edit_replays() const { return *live_edit_replays_; }
  // Live marker sources, all: what their solvers met (the change one frame made).
  void count_marker_frame(const MarkerFrameCounts& before, const MarkerFrameCounts& after) {
    live_markers_.solved += after.solved - before.solved;
    live_markers_.refused += after.refused - before.refused;
    live_markers_.held += after.held - before.held;
    live_markers_.outliers += after.outliers - before.outliers;
    live_markers_.missing += after.missing - before.missing;
  }
  const MarkerFrameCounts& live_markers() const { return live_markers_; }

 private:
  std::vector<LibraryEntry> library_;
  std::map<std::string, std::size_t, std::less<>> by_name_;
  std::uint64_t reloads_ = 0;
  LibraryChanges changes_;  // summed over reloads
  std::vector<std::weak_ptr<const CompiledForm>> compiled_forms_;
  // Live sources (docs/protocol.md, "Live sources"), by name; a source
  // leaves when its publication ends.
  std::map<std::string, std::shared_ptr<LiveSource>, std::less<>> live_;
  std::uint64_t next_live_serial_ = 1;
  std::optional<net::any_io_executor> replay_work_, replay_home_;
  std::uint64_t live_frames_received_ = 0;   // frames published and accepted, all sources
  std::uint64_t live_frames_refused_ = 0;    // refused (wrong size, not finite, unknown publication)
  std::uint64_t live_frames_over_rate_ = 0;  // faster than the declared rate: dropped (RateHold)
  // Edit lists the sources replayed (LiveSource::count_replays), all sources.
  std::shared_ptr<std::uint64_t> live_edit_replays_ = std::make_shared<std::uint64_t>(0);
  MarkerFrameCounts live_markers_;
};

}  // namespace gmr::server
