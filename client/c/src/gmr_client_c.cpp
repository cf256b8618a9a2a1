// The C ABI (gmr_client_c.h) over gmr::client::Client. Nothing C++ crosses
// it: every entry point catches everything, and errors become a status and a
// per-thread message.
#include "gmr_client_c.h"

#include <algorithm>
#include <cstring>
#include <exception>
#include <memory>
#include <mutex>
#include <optional>
#include <map>
#include <string>
#include <string_view>
#include <vector>

#include "gmr/client/client.h"

namespace {

thread_local std::string last_error;

gmr_status fail(gmr_status s, std::string message) {
  last_error = std::move(message);
  return s;
}

// A server refusal's message starts with its code's name (client.cpp).
gmr_status status_of(const gmr::Error& e) {
  const std::string& m = e.message;
  struct Code {
    std::string_view prefix;
    gmr_status status;
  };
  static constexpr Code codes[] = {
      {"BAD_REQUEST:", GMR_ERROR_BAD_REQUEST},
      {"UNKNOWN_REQUEST:", GMR_ERROR_BAD_REQUEST},
      {"NOT_FOUND:", GMR_ERROR_NOT_FOUND},
      {"FAILED_PRECONDITION:", GMR_ERROR_FAILED_PRECONDITION},
      {"RESOURCE_EXHAUSTED:", GMR_ERROR_RESOURCE_EXHAUSTED},
      {"PERMISSION_DENIED:", GMR_ERROR_PERMISSION_DENIED},
      {"UNAUTHENTICATED:", GMR_ERROR_PERMISSION_DENIED},
      {"INTERNAL:", GMR_ERROR_INTERNAL},
  };
  for (const auto& c : codes) {
    if (m.starts_with(c.prefix)) return fail(c.status, m);
  }
  return fail(GMR_ERROR_CONNECTION, e.to_string());
}

void copy_name(char* out, std::size_t size, const std::string& name) {
  const std::size_t n = std::min(size - 1, name.size());
  std::memcpy(out, name.data(), n);
  out[n] = '\0';
}

template <class F>
gmr_status guarded(F&& f) noexcept {
  try {
    return f();
  } catch (const std::exception& e) {
    return fail(GMR_ERROR_INTERNAL, std::string("internal error: ") + e.what());
  } catch (...) {
    return fail(GMR_ERROR_INTERNAL, "internal error");
  }
}

}  // namespace

struct gmr_client {
  std::unique_ptr<gmr::client::Client> client;
};

namespace {

// A view operation on a joint name: checks the arguments, runs `op` on the
// client, maps its result. `what` names the C function for the message.
template <class Op>
gmr_status view_op(const char* what, gmr_client* client, const char* name, Op op) noexcept {
  return guarded([&] {
    if (client == nullptr || name == nullptr)
      return fail(GMR_ERROR_INVALID_ARGUMENT, std::string(what) + ": a NULL argument");
    auto r = op(*client->client, std::string(name));
    return r.ok() ? GMR_OK : status_of(r.error());
  });
}

// A skeleton from gmr_publish_joint entries (gmr_publish, gmr_retarget), or
// the status that says which joint is wrong.
gmr_status skeleton_of(const char* what, const gmr_publish_joint* joints, size_t joint_count, gmr::Skeleton& out) {
  std::vector<gmr::Joint> js;
  js.reserve(joint_count);
  for (std::size_t i = 0; i < joint_count; ++i) {
    const gmr_publish_joint& in = joints[i];
    const std::string where = std::string(what) + ": joint " + std::to_string(i);
    if (in.name == nullptr) return fail(GMR_ERROR_INVALID_ARGUMENT, where + ": a NULL name");
    if (in.channel_count > 6) {
      return fail(GMR_ERROR_INVALID_ARGUMENT,
                  where + ": " + std::to_string(in.channel_count) + " channels (at most 6)");
    }
    gmr::Joint j;
    j.name = in.name;
    j.parent = in.parent;
    j.offset = Eigen::Vector3d(in.offset[0], in.offset[1], in.offset[2]);
    for (std::uint32_t c = 0; c < in.channel_count; ++c) {
      const int type = static_cast<int>(in.channels[c]);
      if (type < 0 || type > 5) {
        return fail(GMR_ERROR_INVALID_ARGUMENT, where + ": channel " + std::to_string(c) + " is not a gmr_channel");
      }
      j.channels.push_back(static_cast<gmr::ChannelType>(type));
    }
    js.push_back(std::move(j));
  }
  auto skeleton = gmr::Skeleton::create(std::move(js));
  if (!skeleton.ok()) return fail(GMR_ERROR_INVALID_ARGUMENT, std::string(what) + ": " + skeleton.error().message);
  out = std::move(skeleton).value();
  return GMR_OK;
}

}  // namespace

// What the client's I/O thread writes and the poller reads. Shared with the
// callbacks, so a callback still running when the handle is freed finds it.
struct SubscriptionState {
  std::mutex mutex;
  std::optional<gmr::client::ReceivedFrame> latest;
  std::uint64_t received = 0, replaced = 0;
  gmr::Skeleton skeleton;
  gmr::RestPose rest;
  std::vector<int> joints;  // joint indices of each frame's values
  // The version of `skeleton` (0: not known yet, before subscribe() returns).
  // Frames of another version are not this skeleton's: a frame of the new
  // version can come before its SkeletonChanged (over UDP), one of the old
  // version after it (already queued); both are dropped, counted as replaced.
  std::uint32_t version = 0;
  bool skeleton_changed = false;
  double metres_per_unit = 0.0;  // of positions and translations (gmr_subscription_metres_per_unit)
  bool ended = false;
  std::string end_reason;
  // The times of the frame the last poll returned (gmr_last_frame_times).
  std::int64_t polled_send_ns = 0, polled_write_ns = 0, polled_receive_ns = 0;

  // The skeleton of the frames from now on (mutex held): a newest frame of
  // another version is dropped.
  void adopt(gmr::Skeleton s, gmr::RestPose r, std::vector<int> j, std::uint32_t v) {
    skeleton = std::move(s);
    rest = std::move(r);
    joints = std::move(j);
    version = v;
    if (latest && latest->skeleton_version != version) {
      latest.reset();
      ++replaced;
    }
  }
};

struct gmr_subscription {
  gmr_client* owner = nullptr;
  std::uint32_t id = 0;
  std::shared_ptr<SubscriptionState> state = std::make_shared<SubscriptionState>();
};

extern "C" {

const char* gmr_last_error(void) { return last_error.c_str(); }

int gmr_abi_version(void) { return GMR_CLIENT_C_ABI_VERSION; }

gmr_status gmr_connect(const char* host, uint16_t port, const char* token, gmr_client** out) {
  return guarded([&] {
    if (out == nullptr) return fail(GMR_ERROR_INVALID_ARGUMENT, "gmr_connect: out is NULL");
    *out = nullptr;
    gmr::client::ClientOptions o;
    if (host != nullptr && *host != '\0') o.host = host;
    o.port = port;
    if (token != nullptr) o.auth_token = token;
    o.client_name = "gmr_client_c";
    auto c = gmr::client::Client::connect(o);
    if (!c.ok()) return status_of(c.error());
    *out = new gmr_client{std::move(c).value()};
    return GMR_OK;
  });
}

void gmr_disconnect(gmr_client* client) {
  if (client == nullptr) return;
  try {
    client->client->close();
  } catch (...) {
  }
  delete client;
}

gmr_status gmr_list_motions(gmr_client* client, gmr_motion_info* out, size_t capacity, size_t* count) {
  return guarded([&] {
    if (client == nullptr || count == nullptr || (out == nullptr && capacity > 0)) {
      return fail(GMR_ERROR_INVALID_ARGUMENT, "gmr_list_motions: a NULL argument");
    }
    auto motions = client->client->list_motions();
    if (!motions.ok()) return status_of(motions.error());
    *count = motions->size();
    for (std::size_t i = 0; i < std::min(capacity, motions->size()); ++i) {
      const auto& m = (*motions)[i];
      copy_name(out[i].name, sizeof out[i].name, m.name);
      out[i].joint_count = m.joint_count;
      out[i].frame_count = m.frame_count;
      out[i].frame_time = m.frame_time;
      out[i].metres_per_unit = m.metres_per_unit;
    }
    return GMR_OK;
  });
}

gmr_status gmr_create_view(gmr_client* client, const char* motion, uint32_t* view_id) {
  return guarded([&] {
    if (client == nullptr || motion == nullptr || view_id == nullptr) {
      return fail(GMR_ERROR_INVALID_ARGUMENT, "gmr_create_view: a NULL argument");
    }
    auto v = client->client->create_view(motion);
    if (!v.ok()) return status_of(v.error());
    *view_id = v->id;
    return GMR_OK;
  });
}

gmr_status gmr_close_view(gmr_client* client, uint32_t view_id) {
  return view_op("gmr_close_view", client, "", [&](auto& c, const std::string&) { return c.close_view(view_id); });
}

gmr_status gmr_shift_root(gmr_client* client, uint32_t view_id, const char* joint) {
  return view_op("gmr_shift_root", client, joint,
                 [&](auto& c, const std::string& j) { return c.shift_root(view_id, j); });
}

gmr_status gmr_set_roots(gmr_client* client, uint32_t view_id, const char* const* roots, size_t count) {
  return guarded([&] {
    if (client == nullptr || (roots == nullptr && count > 0)) {
      return fail(GMR_ERROR_INVALID_ARGUMENT, "gmr_set_roots: a NULL argument");
    }
    std::vector<std::string> names;
    for (std::size_t i = 0; i < count; ++i) {
      if (roots[i] == nullptr)
        return fail(GMR_ERROR_INVALID_ARGUMENT, "gmr_set_roots: root " + std::to_string(i) + " is NULL");
      names.emplace_back(roots[i]);
    }
    auto v = client->client->set_roots(view_id, names);
    return v.ok() ? GMR_OK : status_of(v.error());
  });
}

gmr_status gmr_split(gmr_client* client, uint32_t view_id, const char* joint) {
  return view_op("gmr_split", client, joint, [&](auto& c, const std::string& j) { return c.split(view_id, j); });
}

gmr_status gmr_join(gmr_client* client, uint32_t view_id, const char* root) {
  return view_op("gmr_join", client, root, [&](auto& c, const std::string& r) { return c.join(view_id, r); });
}

gmr_status gmr_strip_dummies(gmr_client* client, uint32_t view_id) {
  return view_op("gmr_strip_dummies", client, "",
                 [&](auto& c, const std::string&) { return c.strip_dummies(view_id); });
}

gmr_status gmr_query_positions(gmr_client* client, uint32_t view_id, uint32_t begin, uint32_t end, gmr_preset preset,
                               double* positions, size_t capacity, size_t* joint_count) {
  return guarded([&] {
    if (client == nullptr || positions == nullptr || joint_count == nullptr) {
      return fail(GMR_ERROR_INVALID_ARGUMENT, "gmr_query_positions: a NULL argument");
    }
    if (preset < GMR_PRESET_NATIVE || preset > GMR_PRESET_GODOT) {
      return fail(GMR_ERROR_INVALID_ARGUMENT, "gmr_query_positions: unknown preset " + std::to_string(preset));
    }
    gmr::client::QueryOptions o;
    o.conventions.preset = static_cast<gmr::ConventionPreset>(preset);
    auto q = client->client->query(view_id, begin, end, o);
    if (!q.ok()) return status_of(q.error());
    *joint_count = q->joints.size();
    if (3 * q->positions.size() > capacity) {
      return fail(GMR_ERROR_INVALID_ARGUMENT, "gmr_query_positions: " + std::to_string(3 * q->positions.size()) +
                                                  " values for an array of " + std::to_string(capacity));
    }
    for (std::size_t i = 0; i < q->positions.size(); ++i) {
      for (int k = 0; k < 3; ++k) positions[3 * i + static_cast<std::size_t>(k)] = q->positions[i][k];
    }
    return GMR_OK;
  });
}

gmr_status gmr_set_viewpoint(gmr_client* client, uint32_t view_id, const char* joint) {
  return view_op("gmr_set_viewpoint", client, joint == nullptr ? "" : joint,
                 [&](auto& c, const std::string& j) { return c.set_coordinates(view_id, j); });
}

void gmr_subscribe_options_init(gmr_subscribe_options* o) {
  if (o == nullptr) return;
  std::memset(o, 0, sizeof *o);
  o->struct_size = sizeof *o;
  o->speed = 1.0;
  o->preset = GMR_PRESET_NATIVE;
}

gmr_status gmr_subscribe(gmr_client* client, uint32_t view_id, const gmr_subscribe_options* options,
                         gmr_subscription** out) {
  return guarded([&] {
    if (client == nullptr || options == nullptr || out == nullptr) {
      return fail(GMR_ERROR_INVALID_ARGUMENT, "gmr_subscribe: a NULL argument");
    }
    *out = nullptr;
    if (options->struct_size != sizeof(gmr_subscribe_options)) {
      return fail(GMR_ERROR_INVALID_ARGUMENT,
                  "gmr_subscribe: options not set up by gmr_subscribe_options_init "
                  "(struct_size " +
                      std::to_string(options->struct_size) + ", expected " +
                      std::to_string(sizeof(gmr_subscribe_options)) + ")");
    }
    if (options->preset < GMR_PRESET_NATIVE || options->preset > GMR_PRESET_GODOT) {
      return fail(GMR_ERROR_INVALID_ARGUMENT, "gmr_subscribe: unknown preset " + std::to_string(options->preset));
    }
    gmr::client::SubscribeOptions o;
    o.start_frame = options->start_frame;
    o.end_frame = options->end_frame;
    o.loop = options->loop != 0;
    o.speed = options->speed;
    o.rate_hz = options->rate_hz;
    o.orientations = options->orientations != 0;
    o.local_transforms = options->local_transforms != 0;
    o.udp = options->udp != 0;
    o.float64 = options->float64 != 0;
    o.max_frames = options->max_frames;
    o.conventions.preset = static_cast<gmr::ConventionPreset>(options->preset);
    o.conventions.source_metres_per_unit = options->source_metres_per_unit;
    if (options->max_staleness_ms != 0) o.max_staleness = std::chrono::milliseconds(options->max_staleness_ms);
    auto sub = std::make_unique<gmr_subscription>();
    sub->owner = client;
    const std::shared_ptr<SubscriptionState> state = sub->state;
    auto on_frame = [state](const gmr::client::ReceivedFrame& f) {
      SubscriptionState* s = state.get();
      std::lock_guard lock(s->mutex);
      ++s->received;
      if (s->version != 0 && f.skeleton_version != s->version) {
        ++s->replaced;
        return;
      }
      if (s->latest) ++s->replaced;
      s->latest = f;
    };
    auto on_end = [state](const gmr::client::SubscriptionEnd& e) {
      SubscriptionState* s = state.get();
      std::lock_guard lock(s->mutex);
      s->ended = true;
      s->end_reason = e.reason;
    };
    auto on_skeleton = [state](const gmr::client::SkeletonChange& c) {
      SubscriptionState* s = state.get();
      std::lock_guard lock(s->mutex);
      s->adopt(c.skeleton, c.rest, c.joints, c.skeleton_version);
      s->skeleton_changed = true;
    };
    auto info = client->client->subscribe(view_id, o, on_frame, on_end, on_skeleton);
    if (!info.ok()) return status_of(info.error());
    {
      // The callbacks may run before subscribe() returns: a skeleton change
      // that came first is newer than the reply's skeleton, and is kept.
      std::lock_guard lock(state->mutex);
      if (!state->skeleton_changed) state->adopt(info->skeleton, info->rest, info->joints, info->skeleton_version);
      state->skeleton_changed = false;
      state->metres_per_unit = info->metres_per_unit;
    }
    sub->id = info->id;
    *out = sub.release();
    return GMR_OK;
  });
}

void gmr_unsubscribe(gmr_subscription* subscription) {
  if (subscription == nullptr) return;
  try {
    bool ended;
    {
      std::lock_guard lock(subscription->state->mutex);
      ended = subscription->state->ended;
    }
    // After this the client calls none of the subscription's callbacks.
    if (!ended && subscription->owner->client->connected())
      (void)subscription->owner->client->unsubscribe(subscription->id);
  } catch (...) {
  }
  delete subscription;
}

gmr_status gmr_subscription_joint_count(gmr_subscription* s, size_t* count) {
  return guarded([&] {
    if (s == nullptr || count == nullptr)
      return fail(GMR_ERROR_INVALID_ARGUMENT, "gmr_subscription_joint_count: a NULL argument");
    SubscriptionState& st = *s->state;
    std::lock_guard lock(st.mutex);
    *count = st.skeleton.size();
    return GMR_OK;
  });
}

gmr_status gmr_subscription_metres_per_unit(gmr_subscription* s, double* metres_per_unit) {
  return guarded([&] {
    if (s == nullptr || metres_per_unit == nullptr)
      return fail(GMR_ERROR_INVALID_ARGUMENT, "gmr_subscription_metres_per_unit: a NULL argument");
    SubscriptionState& st = *s->state;
    std::lock_guard lock(st.mutex);
    *metres_per_unit = st.metres_per_unit;
    return GMR_OK;
  });
}

gmr_status gmr_subscription_joint(gmr_subscription* s, size_t index, gmr_joint_info* out) {
  return guarded([&] {
    if (s == nullptr || out == nullptr)
      return fail(GMR_ERROR_INVALID_ARGUMENT, "gmr_subscription_joint: a NULL argument");
    SubscriptionState& st = *s->state;
    std::lock_guard lock(st.mutex);
    if (index >= st.skeleton.size()) {
      return fail(GMR_ERROR_INVALID_ARGUMENT, "gmr_subscription_joint: joint " + std::to_string(index) + " of " +
                                                  std::to_string(st.skeleton.size()));
    }
    const auto& j = st.skeleton.joint(static_cast<int>(index));
    copy_name(out->name, sizeof out->name, j.name);
    out->parent = j.parent;
    const bool have_rest = index < st.rest.translations.size();
    const Eigen::Vector3d t = have_rest ? st.rest.translations[index] : j.offset;
    const Eigen::Quaterniond q = have_rest ? st.rest.rotations[index] : Eigen::Quaterniond::Identity();
    for (int k = 0; k < 3; ++k) out->rest_translation[k] = t[k];
    out->rest_rotation[0] = q.x();
    out->rest_rotation[1] = q.y();
    out->rest_rotation[2] = q.z();
    out->rest_rotation[3] = q.w();
    return GMR_OK;
  });
}

gmr_status gmr_poll_frame(gmr_subscription* s, gmr_frame* frame, double* positions, double* orientations,
                          double* local_rotations, double* local_translations, size_t capacity) {
  return guarded([&] {
    if (s == nullptr || frame == nullptr) return fail(GMR_ERROR_INVALID_ARGUMENT, "gmr_poll_frame: a NULL argument");
    std::optional<gmr::client::ReceivedFrame> f;
    bool changed = false;
    {
      SubscriptionState& st = *s->state;
      std::lock_guard lock(st.mutex);
      if (!st.latest) {
        if (st.ended) return fail(GMR_ENDED, "the subscription ended: " + st.end_reason);
        return fail(GMR_NO_FRAME, "no new frame");
      }
      if (st.latest->positions.size() > capacity) {
        return fail(GMR_ERROR_INVALID_ARGUMENT, "gmr_poll_frame: the frame has " +
                                                    std::to_string(st.latest->positions.size()) +
                                                    " joints, the arrays hold " + std::to_string(capacity));
      }
      f.swap(st.latest);
      changed = st.skeleton_changed;
      st.skeleton_changed = false;
      st.polled_send_ns = f->server_send_time_ns;
      st.polled_write_ns = f->server_write_time_ns;
      st.polled_receive_ns = f->receive_time_ns;
    }
    const std::size_t n = f->positions.size();
    frame->frame_index = f->frame_index;
    frame->motion_time = f->motion_time;
    frame->sequence = f->sequence;
    frame->server_send_time_ns = f->server_send_time_ns;
    frame->skeleton_version = f->skeleton_version;
    frame->joint_count = static_cast<uint32_t>(n);
    frame->skeleton_changed = changed ? 1 : 0;
    frame->has_local_transforms = f->local_rotations.size() == n && n > 0 ? 1 : 0;
    frame->has_orientations = f->orientations.size() == n && n > 0 ? 1 : 0;
    for (std::size_t i = 0; i < n; ++i) {
      if (positions != nullptr) {
        for (int k = 0; k < 3; ++k) positions[3 * i + k] = f->positions[i][k];
      }
      if (orientations != nullptr && frame->has_orientations) {
        const auto& q = f->orientations[i];
        const double v[] = {q.x(), q.y(), q.z(), q.w()};
        std::memcpy(orientations + 4 * i, v, sizeof v);
      }
      if (frame->has_local_transforms) {
        if (local_rotations != nullptr) {
          const auto& q = f->local_rotations[i];
          const double v[] = {q.x(), q.y(), q.z(), q.w()};
          std::memcpy(local_rotations + 4 * i, v, sizeof v);
        }
        if (local_translations != nullptr) {
          for (int k = 0; k < 3; ++k) local_translations[3 * i + k] = f->local_translations[i][k];
        }
      }
    }
    return GMR_OK;
  });
}

gmr_status gmr_last_frame_times(gmr_subscription* s, int64_t* server_send_time_ns, int64_t* server_write_time_ns,
                                int64_t* receive_time_ns) {
  return guarded([&] {
    if (s == nullptr) return fail(GMR_ERROR_INVALID_ARGUMENT, "gmr_last_frame_times: subscription is NULL");
    SubscriptionState& st = *s->state;
    std::lock_guard lock(st.mutex);
    if (server_send_time_ns != nullptr) *server_send_time_ns = st.polled_send_ns;
    if (server_write_time_ns != nullptr) *server_write_time_ns = st.polled_write_ns;
    if (receive_time_ns != nullptr) *receive_time_ns = st.polled_receive_ns;
    return GMR_OK;
  });
}

gmr_status gmr_subscription_counts(gmr_subscription* s, uint64_t* received, uint64_t* replaced) {
  return guarded([&] {
    if (s == nullptr) return fail(GMR_ERROR_INVALID_ARGUMENT, "gmr_subscription_counts: subscription is NULL");
    SubscriptionState& st = *s->state;
    std::lock_guard lock(st.mutex);
    if (received != nullptr) *received = st.received;
    if (replaced != nullptr) *replaced = st.replaced;
    return GMR_OK;
  });
}

}  // extern "C"

gmr_status gmr_retarget(gmr_client* client, uint32_t view_id, const gmr_publish_joint* joints, size_t joint_count,
                        const double* reference, size_t reference_count) {
  return gmr_retarget_mapped(client, view_id, joints, joint_count, reference, reference_count, nullptr, 0, nullptr, 0,
                             0.0);
}

gmr_status gmr_retarget_mapped(gmr_client* client, uint32_t view_id, const gmr_publish_joint* joints,
                               size_t joint_count, const double* reference, size_t reference_count,
                               const gmr_role_joint* rig_map, size_t rig_map_count, const gmr_role_joint* source_map,
                               size_t source_map_count, double metres_per_unit) {
  return guarded([&] {
    if (client == nullptr || (joints == nullptr && joint_count > 0) || (reference == nullptr && reference_count > 0) ||
        (rig_map == nullptr && rig_map_count > 0) || (source_map == nullptr && source_map_count > 0)) {
      return fail(GMR_ERROR_INVALID_ARGUMENT, "gmr_retarget: a NULL argument");
    }
    gmr::Skeleton rig;
    if (const gmr_status bad = skeleton_of("gmr_retarget", joints, joint_count, rig); bad != GMR_OK) return bad;
    std::map<std::string, std::string> maps[2];
    const gmr_role_joint* given[2] = {rig_map, source_map};
    const size_t counts[2] = {rig_map_count, source_map_count};
    for (int m = 0; m < 2; ++m) {
      const std::string what = m == 0 ? "gmr_retarget: the rig's map" : "gmr_retarget: the source's map";
      for (size_t i = 0; i < counts[m]; ++i) {
        const gmr_role_joint& e = given[m][i];
        if (e.role == nullptr || e.joint == nullptr) {
          return fail(GMR_ERROR_INVALID_ARGUMENT, what + ": entry " + std::to_string(i) + " has a NULL role or joint");
        }
        if (!maps[m].emplace(e.role, e.joint).second) {
          return fail(GMR_ERROR_INVALID_ARGUMENT, what + ": role '" + e.role + "' is given twice");
        }
      }
    }
    auto v = client->client->retarget(view_id, rig, std::vector<double>(reference, reference + reference_count),
                                      maps[0], maps[1], metres_per_unit);
    return v.ok() ? GMR_OK : status_of(v.error());
  });
}

gmr_status gmr_publish(gmr_client* client, const char* name, const gmr_publish_joint* joints, size_t joint_count,
                       double frame_time, double metres_per_unit, uint32_t* publication_id) {
  return guarded([&] {
    if (client == nullptr || name == nullptr || (joints == nullptr && joint_count > 0) || publication_id == nullptr) {
      return fail(GMR_ERROR_INVALID_ARGUMENT, "gmr_publish: a NULL argument");
    }
    gmr::Skeleton skeleton;
    if (const gmr_status bad = skeleton_of("gmr_publish", joints, joint_count, skeleton); bad != GMR_OK) return bad;
    gmr::client::PublishOptions o;
    o.name = name;
    o.frame_time = frame_time;
    o.metres_per_unit = metres_per_unit;
    auto id = client->client->publish(skeleton, o);
    if (!id.ok()) return status_of(id.error());
    *publication_id = id->id;
    return GMR_OK;
  });
}

gmr_status gmr_publish_frame(gmr_client* client, uint32_t publication_id, const double* values, size_t count) {
  return guarded([&] {
    if (client == nullptr || (values == nullptr && count > 0)) {
      return fail(GMR_ERROR_INVALID_ARGUMENT, "gmr_publish_frame: a NULL argument");
    }
    auto s = client->client->publish_frame(publication_id, std::span<const double>(values, count));
    if (!s.ok()) {
      return s.error().kind == gmr::ErrorKind::kResourceExhausted
                 ? fail(GMR_ERROR_RESOURCE_EXHAUSTED, s.error().message)
                 : status_of(s.error());
    }
    // The server's word on an earlier frame.
    const auto errors = client->client->take_errors();
    if (!errors.empty()) return status_of(gmr::make_error(errors.front()));
    return GMR_OK;
  });
}

gmr_status gmr_unpublish(gmr_client* client, uint32_t publication_id) {
  return guarded([&] {
    if (client == nullptr) return fail(GMR_ERROR_INVALID_ARGUMENT, "gmr_unpublish: a NULL argument");
    auto s = client->client->unpublish(publication_id);
    if (!s.ok()) return status_of(s.error());
    return GMR_OK;
  });
}
