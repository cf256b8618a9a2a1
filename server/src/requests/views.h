// Views: one session's views (docs/protocol.md, "Views") and the requests
// about them: the library listed, skeletons, views made of library motions
// and live sources, structural edits committed under the view budget,
// coordinates, frame queries. The session runs long edits off the control
// loop and commits them here.
#pragma once

#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "gmr/server/view.h"
#include "requests/session_link.h"

namespace gmr::server {

class Views {
 public:
  explicit Views(SessionLink& link) : link_(link) {}
  // `changed` is told when a view's content changed (an edit, coordinates).
  void on_changed(std::function<void(const View&)> changed) { changed_ = std::move(changed); }

  Reply list_motions() const;
  Reply get_skeleton(const pb::GetSkeleton& r) const;
  Reply create(const pb::CreateView& r);
  // Forgets view `id` and gives its bytes back (its subscriptions are the caller's).
  void close(std::uint32_t id);
  // Installs what an edit of view `view_id` computed, under the view budget;
  // the reply (`decorate` adds what the edit reports to it).
  using EditDecoration = void (*)(const EditReport&, pb::ViewInfo&);
  Reply commit_edit(std::uint32_t view_id, const ViewEdit& edit, Result<std::shared_ptr<const ViewContent>> next,
                    EditDecoration decorate);
  Reply set_coordinates(const pb::SetCoordinates& r);
  Reply query(const pb::QueryFrames& r) const;

  // The view, or null.
  View* find(std::uint32_t id) const;
  // The indices of `names` in the view (all its joints when empty), or the
  // first unknown name's error.
  Result<std::vector<int>> resolve_joints(const View& v, const std::vector<std::string>& names) const;
  std::size_t count() const { return views_.size(); }
  // Forgets every view (the connection stopped).
  void clear();

 private:
  pb::ViewInfo info(const View& v) const;
  void forget(const View& v);

  SessionLink& link_;
  std::function<void(const View&)> changed_;
  std::map<std::uint32_t, std::unique_ptr<View>> views_;
  std::uint32_t next_view_ = 1;
};

}  // namespace gmr::server
