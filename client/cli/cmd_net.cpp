// Server commands: ls, skeleton, query, stream, record, publish (a running
// gmr-server), and discover (the servers on this network).
// Built only with GMR_BUILD_NET (GMR_WITH_NET); otherwise add_net_commands adds nothing.
#include "commands.h"

#ifdef GMR_WITH_NET

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <cstring>
#include <functional>
#include <iostream>
#include <memory>
#include <mutex>
#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <map>
#include <sstream>
#include <thread>

#include "cli_util.h"
#include "cmd_ops.h"
#include "connect_options.h"
#include "gmr/client/client.h"
#include "gmr/core/file_util.h"
#include "gmr/io/motion_file.h"
#include "gmr/io/positions_csv.h"
#include "gmr/markers/markers.h"
#include "gmr/ops/convert.h"
#include "gmr/stream/v1/stream.pb.h"

namespace gmr::cli {
namespace {

using ServerOptions = client::ClientOptions;

std::unique_ptr<client::Client> connect(ServerOptions o) {
  o.client_name = "gmr cli";
  return take(client::Client::connect(o));
}

// Rows in the motion's own joint order (as `gmr positions` prints them):
// the view's joints mapped back by name, joints the view lost left out.
struct RowOrder {
  Skeleton names;                 // unlinked joints, for write_positions_csv_rows
  std::vector<std::size_t> from;  // row r takes value index from[r] of a frame
};
RowOrder row_order(const Skeleton& source, const Skeleton& view, const std::vector<int>& joints) {
  RowOrder o;
  std::vector<Joint> js;
  for (const auto& j : source.joints()) {
    const int vj = view.find(j.name);
    const auto it = std::find(joints.begin(), joints.end(), vj);
    if (vj < 0 || it == joints.end()) continue;
    Joint n;
    n.name = shown(j.name);  // printed: a server's names never reach the terminal raw
    js.push_back(std::move(n));
    o.from.push_back(static_cast<std::size_t>(it - joints.begin()));
  }
  o.names = take(Skeleton::create(std::move(js)));
  return o;
}

// Applies --roots, --strip-dummies, --relative-to to a server view.
client::ViewState make_view(client::Client& c, const std::string& motion, const ViewOptions& o) {
  client::ViewState v = take(c.create_view(motion));
  if (!o.roots.empty()) v = take(c.set_roots(v.id, split_list(o.roots)));
  if (o.strip_dummies) v = take(c.strip_dummies(v.id));
  if (!o.relative_to.empty()) v = take(c.set_coordinates(v.id, o.relative_to));
  return v;
}

// The unit the server knows `motion` in (0: unknown), for the warning.
double served_unit(client::Client& c, const std::string& motion) {
  for (const auto& m : take(c.list_motions())) {
    if (m.name == motion) return m.metres_per_unit;
  }
  return 0.0;
}

// ---- gmr ls
void run_ls(const ServerOptions& s) {
  auto c = connect(s);
  const auto motions = take(c->list_motions());
  std::printf("%-32s %7s %8s %8s %9s  %s\n", "motion", "joints", "frames", "fps", "seconds", "source");
  for (const auto& m : motions) {
    const double fps = m.frame_time > 0 ? 1.0 / m.frame_time : 0.0;
    std::printf("%-32s %7u %8llu %8.2f %9.2f  %s\n", shown(m.name).c_str(), m.joint_count,
                static_cast<unsigned long long>(m.frame_count), fps, m.frame_time * static_cast<double>(m.frame_count),
                shown(m.source).c_str());
  }
}

// ---- gmr skeleton
void run_skeleton(const ServerOptions& s, const std::string& motion) {
  auto c = connect(s);
  const Skeleton sk = take(c->skeleton(motion));
  std::printf("%s: %zu joints, %zu roots\n", shown(motion).c_str(), sk.size(), sk.roots().size());
  for (int j = 0; j < static_cast<int>(sk.size()); ++j) {
    const Joint& jt = sk.joint(j);
    std::string channels;
    for (auto ch : jt.channels) {
      if (!channels.empty()) channels += ' ';
      channels += channel_name(ch);
    }
    std::printf("%s%s  offset %s %s %s%s%s\n", tree_indent(sk.depth(j)).c_str(), shown(jt.name).c_str(),
                format_double(jt.offset.x()).c_str(), format_double(jt.offset.y()).c_str(),
                format_double(jt.offset.z()).c_str(), channels.empty() ? "" : "  channels ", channels.c_str());
  }
}

// ---- gmr query
struct QueryOptions {
  ServerOptions server;
  std::string motion;
  std::string frames = ":";
  ViewOptions view;
  std::string orientations;  // "", "quat" or "matrix"
  bool local_transforms = false;
};

void run_query(const QueryOptions& o) {
  const FrameRange requested = parse_frame_range(o.frames);
  auto c = connect(o.server);
  const Skeleton source = take(c->skeleton(o.motion));
  if (o.view.conventions != "native") warn_if_unit_unknown(o.view, served_unit(*c, o.motion));
  const client::ViewState v = make_view(*c, o.motion, o.view);
  const FrameRange r = clamp_frame_range(requested, v.frame_count);
  const PoseColumns columns = pose_columns(o.orientations, o.local_transforms);
  const bool with_orientations = columns.orientations.has_value();
  write_pose_header(std::cout, columns);
  // Chunks keep each reply well under the server's message limit.
  const std::size_t per_frame =
      v.skeleton.size() * (3 + (with_orientations ? 4 : 0) + (o.local_transforms ? 7 : 0)) * 9 + 16;
  const std::size_t chunk = std::max<std::size_t>(1, c->hello().max_message_bytes / 2 / per_frame);
  client::QueryOptions qo;
  qo.orientations = with_orientations;
  qo.local_transforms = o.local_transforms;
  qo.conventions = o.view.engine();
  RowOrder order;
  bool have_order = false;
  for (std::size_t f = r.begin; f < r.end; f += chunk) {
    const std::size_t e = std::min(r.end, f + chunk);
    const auto q = take(c->query(v.id, static_cast<std::uint32_t>(f), static_cast<std::uint32_t>(e), qo));
    if (!have_order) {
      order = row_order(source, v.skeleton, q.joints);
      have_order = true;
    }
    const std::size_t n = q.joints.size();
    if (q.positions.size() != (e - f) * n || (with_orientations && q.orientations.size() != (e - f) * n) ||
        (o.local_transforms &&
         (q.local_rotations.size() != (e - f) * n || q.local_translations.size() != (e - f) * n))) {
      throw CommandError("the server's frames " + std::to_string(f) + "-" + std::to_string(e) + " do not carry " +
                         std::to_string(n) + " joints each");
    }
    std::vector<Eigen::Vector3d> rows, shifts;
    std::vector<Eigen::Matrix3d> turns;
    std::vector<Eigen::Quaterniond> locals;
    rows.reserve((e - f) * order.from.size());
    for (std::size_t k = 0; k < e - f; ++k) {
      for (std::size_t from : order.from) {
        rows.push_back(q.positions[k * n + from]);
        if (with_orientations) turns.push_back(q.orientations[k * n + from].toRotationMatrix());
        if (o.local_transforms) {
          locals.push_back(q.local_rotations[k * n + from]);
          shifts.push_back(q.local_translations[k * n + from]);
        }
      }
    }
    write_pose_rows(std::cout, order.names, {rows, turns, locals, shifts}, f, columns);
  }
  std::cout.flush();
  if (!std::cout) throw CommandError("cannot write the positions to standard output");
}

// ---- what `gmr stream` and `gmr record` play

struct PlayOptions {
  ServerOptions server;
  std::string motion;
  ViewOptions view;
  bool udp = false;
  bool multicast = false;
  double rate = 0.0;
  double speed = 1.0;
  std::uint64_t count = 0;
  bool loop = false;
  std::string joints;
  std::string frames = ":";
};

void add_play_options(CLI::App& cmd, PlayOptions& o) {
  cmd.add_option("motion", o.motion, "Motion name (see gmr ls)")->required();
  cmd.add_flag("--udp", o.udp, "Receive frames over UDP (registered with the session token)");
  cmd.add_flag("--multicast", o.multicast,
               "Receive a shared stream from the server's multicast group (gmr-server --multicast-group)");
  cmd.add_option("--rate", o.rate, "Rate in Hz (default: the motion's own rate times --speed)");
  cmd.add_option("--speed", o.speed, "Playback speed")->capture_default_str();
  cmd.add_option("--count", o.count, "Stop after N frames");
  cmd.add_flag("--loop", o.loop, "Loop the frame range");
  cmd.add_option("--frames", o.frames, "Half-open frame range A:B to play")->capture_default_str();
  cmd.add_option("--joints", o.joints, "Only these joints, A,B,C");
  add_view_options(cmd, o.view);
  add_connect_options(cmd, o.server);
}

// The subscription PlayOptions ask for, on view v.
client::SubscribeOptions subscribe_options(const PlayOptions& o, const client::ViewState& v) {
  const FrameRange r = clamp_frame_range(parse_frame_range(o.frames), v.frame_count);
  client::SubscribeOptions so;
  so.udp = o.udp;
  so.multicast = o.multicast;
  so.rate_hz = o.rate;
  so.speed = o.speed;
  so.loop = o.loop;
  so.max_frames = o.count;
  so.start_frame = static_cast<std::uint32_t>(r.begin);
  so.end_frame = static_cast<std::uint32_t>(r.end);
  if (!o.joints.empty()) so.joints = split_list(o.joints);
  so.conventions = o.view.engine();
  return so;
}

// ---- gmr stream
struct StreamOptions : PlayOptions {
  bool summary = false;
  std::string orientations;  // "", "quat" or "matrix"
  bool local_transforms = false;
};

void run_stream(const StreamOptions& o) {
  auto c = connect(o.server);
  const Skeleton source = take(c->skeleton(o.motion));
  if (o.view.conventions != "native") warn_if_unit_unknown(o.view, served_unit(*c, o.motion));
  const client::ViewState v = make_view(*c, o.motion, o.view);
  client::SubscribeOptions so = subscribe_options(o, v);
  so.float64 = !o.summary;  // CSV prints exact numbers
  so.orientations = !o.orientations.empty();
  so.local_transforms = o.local_transforms;
  const PoseColumns columns = pose_columns(o.orientations, o.local_transforms);

  struct State {
    std::mutex mutex;
    std::condition_variable cv;
    bool done = false;
    std::string end_reason;
    std::uint64_t frames = 0, gaps = 0, last_sequence = 0, last_frame = 0;
    std::uint64_t dropped = 0, skipped = 0;  // from the end notice: the client was slow / the server was late
    std::uint64_t unfit = 0;                 // frames whose values do not fit the view's joints (not printed)
    std::int64_t latency_sum_ns = 0, latency_max_ns = 0;
    std::uint64_t window_frames = 0;
    std::int64_t window_latency_sum = 0, window_latency_max = 0;
  };
  auto st = std::make_shared<State>();
  RowOrder order;
  std::atomic<bool> have_order{false};
  std::size_t values = 0;  // per frame: one per joint subscribed
  std::mutex out_mutex;
  if (!o.summary) write_pose_header(std::cout, columns);
  const auto started = std::chrono::steady_clock::now();

  auto on_frame = [&, st](const client::ReceivedFrame& f) {
    const std::int64_t latency = f.receive_time_ns - f.server_send_time_ns;
    {
      std::lock_guard lock(st->mutex);
      if (st->frames > 0 && f.sequence > st->last_sequence + 1) st->gaps += f.sequence - st->last_sequence - 1;
      ++st->frames;
      st->last_sequence = f.sequence;
      st->last_frame = f.frame_index;
      st->latency_sum_ns += latency;
      st->latency_max_ns = std::max(st->latency_max_ns, latency);
      ++st->window_frames;
      st->window_latency_sum += latency;
      st->window_latency_max = std::max(st->window_latency_max, latency);
    }
    if (f.positions.size() != values || (so.orientations && f.orientations.size() != values) ||
        (so.local_transforms && (f.local_rotations.size() != values || f.local_translations.size() != values))) {
      // The client checks frames against the joints the server named; these
      // are the joints this command asked for.
      std::lock_guard lock(st->mutex);
      ++st->unfit;
      return;
    }
    if (!o.summary && have_order) {
      std::vector<Eigen::Vector3d> rows, shifts;
      std::vector<Eigen::Matrix3d> turns;
      std::vector<Eigen::Quaterniond> locals;
      for (std::size_t from : order.from) {
        rows.push_back(f.positions[from]);
        if (so.orientations) turns.push_back(f.orientations[from].toRotationMatrix());
        if (so.local_transforms) {
          locals.push_back(f.local_rotations[from]);
          shifts.push_back(f.local_translations[from]);
        }
      }
      std::lock_guard lock(out_mutex);
      write_pose_rows(std::cout, order.names, {rows, turns, locals, shifts}, f.frame_index, columns);
    }
  };
  auto on_end = [st](const client::SubscriptionEnd& e) {
    std::lock_guard lock(st->mutex);
    st->done = true;
    st->end_reason = e.reason;
    st->dropped = e.frames_dropped;
    st->skipped = e.frames_skipped;
    st->cv.notify_all();
  };
  // Row order must be known before the first frame prints: take it from the
  // view (all joints or the subset, in the order the server will send).
  {
    std::vector<int> joints;
    if (so.joints.empty()) {
      for (int j = 0; j < static_cast<int>(v.skeleton.size()); ++j) joints.push_back(j);
    } else {
      for (const auto& n : so.joints) joints.push_back(v.skeleton.find(n));
    }
    order = row_order(source, v.skeleton, joints);
    values = joints.size();
    have_order = true;
  }
  const auto sub = take(c->subscribe(v.id, so, on_frame, on_end));
  if (o.summary) {
    std::fprintf(stderr, "streaming %s over %s at %.2f Hz (subscription %u, view %u)\n", o.motion.c_str(),
                 o.multicast ? "multicast"
                 : o.udp     ? "UDP"
                             : "TCP",
                 sub.rate_hz, sub.id, v.id);
  }
  std::unique_lock lock(st->mutex);
  for (;;) {
    st->cv.wait_for(lock, std::chrono::milliseconds(500), [&] { return st->done || !c->connected(); });
    if (o.summary && st->window_frames > 0) {
      const double t = std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
      std::printf("t=%6.2fs  frames %6llu  last frame %6llu  seq %6llu  latency avg %.3f ms max %.3f ms  gaps %llu\n",
                  t, static_cast<unsigned long long>(st->frames), static_cast<unsigned long long>(st->last_frame),
                  static_cast<unsigned long long>(st->last_sequence),
                  static_cast<double>(st->window_latency_sum) / static_cast<double>(st->window_frames) / 1e6,
                  static_cast<double>(st->window_latency_max) / 1e6, static_cast<unsigned long long>(st->gaps));
      std::fflush(stdout);
      st->window_frames = 0;
      st->window_latency_sum = 0;
      st->window_latency_max = 0;
    }
    if (st->done) break;
    if (!c->connected()) throw CommandError("the server closed the connection");
  }
  const auto frames = st->frames;
  const auto gaps = st->gaps;
  const auto reason = st->end_reason;
  const auto dropped = st->dropped, skipped = st->skipped;
  const auto unfit = st->unfit;
  const double avg = frames ? static_cast<double>(st->latency_sum_ns) / static_cast<double>(frames) / 1e6 : 0.0;
  const double max = static_cast<double>(st->latency_max_ns) / 1e6;
  lock.unlock();
  std::cout.flush();
  if (o.summary) {
    // Gaps in the sequence numbers: frames this client read too slowly (the
    // server dropped them), ticks the server skipped being late, and the rest,
    // lost on the way (UDP).
    const std::uint64_t server_side = dropped + skipped;
    std::printf(
        "done: %llu frames (%s), %llu gaps: %llu dropped for a slow reader, %llu skipped by a late server, "
        "%llu lost in transit; latency avg %.3f ms, max %.3f ms\n",
        static_cast<unsigned long long>(frames), shown(reason).c_str(), static_cast<unsigned long long>(gaps),
        static_cast<unsigned long long>(dropped), static_cast<unsigned long long>(skipped),
        static_cast<unsigned long long>(gaps > server_side ? gaps - server_side : 0), avg, max);
  }
  if (!o.summary && !reason.empty() && reason != "end of motion" && reason != "max_frames reached") {
    // The server ended it for its own reason (a live source ended, the library changed): say so.
    std::fprintf(stderr, "gmr stream: the subscription ended: %s\n", shown(reason).c_str());
  }
  if (!std::cout) throw CommandError("cannot write to standard output");
  // Frames the client found malformed (values that do not decode or do not
  // fit the joints the server named) and frames that do not fit the joints
  // asked for: the output lacks them, which is an error.
  const std::uint64_t malformed = c->counters().frames_malformed + unfit;
  if (malformed > 0) {
    throw CommandError(std::to_string(malformed) + " frames from the server did not carry the " +
                       std::to_string(values) + " joints subscribed: not printed");
  }
}

// ---- gmr record

struct RecordOptions : PlayOptions {
  std::string out;
  double seconds = 0.0;
};

// Subscribes (float64, with orientations) and writes what arrives as a GMR
// motion: every recorded joint a root holding its world position and
// orientation, soft-linked to its nearest recorded ancestor in the view
// (motion_from_world_poses). A frame lost on the way (UDP) is filled with the
// one before it, and counted.
constexpr std::uint64_t kMaxFilledGap = 1 << 16;  // frames: 9 minutes at 120 Hz

void run_record(const RecordOptions& o) {
  const std::string ext = lower_extension(o.out);
  if (ext != ".gmr" && ext != ".gmrb" && ext != ".bvh") {
    throw CommandError(o.out + ": a recording is written as .gmr, .gmrb or .bvh");
  }
  auto c = connect(o.server);
  const client::ViewState v = make_view(*c, o.motion, o.view);
  client::SubscribeOptions so = subscribe_options(o, v);
  so.float64 = true;
  so.orientations = true;

  struct State {
    std::mutex mutex;
    std::condition_variable cv;
    bool done = false;
    std::string end_reason;
    std::vector<Eigen::Vector3d> positions;
    std::vector<Eigen::Quaterniond> orientations;
    std::uint64_t frames = 0, filled = 0, last_sequence = 0;
    std::size_t values = 0;  // per frame, from the first frame
    std::string problem;     // a frame that cannot be recorded ends the recording
  };
  auto st = std::make_shared<State>();
  auto on_frame = [st](const client::ReceivedFrame& f) {
    std::lock_guard lock(st->mutex);
    if (st->done) return;
    const std::size_t n = f.positions.size();
    auto stop = [&](std::string why) {
      st->problem = std::move(why);
      st->done = true;
      st->cv.notify_all();
    };
    if (st->frames == 0) st->values = n;
    if (n == 0 || n != st->values || f.orientations.size() != n) {
      return stop("frame " + std::to_string(f.frame_index) + " carries " + std::to_string(n) + " positions and " +
                  std::to_string(f.orientations.size()) + " orientations (expected " + std::to_string(st->values) +
                  " of each)");
    }
    // A gap in the sequence: repeat the last frame so frame times stay even;
    // a jump no stream makes is the server's error, not a gap to fill.
    if (st->frames > 0 && f.sequence > st->last_sequence && f.sequence - st->last_sequence > kMaxFilledGap) {
      return stop("the sequence jumped from " + std::to_string(st->last_sequence) + " to " +
                  std::to_string(f.sequence));
    }
    for (std::uint64_t s = st->last_sequence + 1; st->frames > 0 && s < f.sequence; ++s) {
      st->positions.insert(st->positions.end(), st->positions.end() - static_cast<std::ptrdiff_t>(n),
                           st->positions.end());
      st->orientations.insert(st->orientations.end(), st->orientations.end() - static_cast<std::ptrdiff_t>(n),
                              st->orientations.end());
      ++st->filled;
    }
    st->positions.insert(st->positions.end(), f.positions.begin(), f.positions.end());
    st->orientations.insert(st->orientations.end(), f.orientations.begin(), f.orientations.end());
    ++st->frames;
    st->last_sequence = f.sequence;
  };
  auto on_end = [st](const client::SubscriptionEnd& e) {
    std::lock_guard lock(st->mutex);
    st->done = true;
    st->end_reason = e.reason;
    st->cv.notify_all();
  };
  const client::SubscriptionInfo sub = take(c->subscribe(v.id, so, on_frame, on_end));
  bool stopped_here = false;
  {
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(o.seconds);
    std::unique_lock lock(st->mutex);
    for (;;) {
      st->cv.wait_for(lock, std::chrono::milliseconds(200), [&] { return st->done || !c->connected(); });
      if (st->done) break;
      if (o.seconds > 0 && std::chrono::steady_clock::now() >= deadline) {
        st->done = true;
        st->end_reason = "--seconds reached";
        stopped_here = true;
        break;
      }
      if (!c->connected()) throw CommandError("the server closed the connection");
    }
  }
  if (stopped_here) check(c->unsubscribe(sub.id));
  std::lock_guard lock(st->mutex);
  if (!st->problem.empty()) throw CommandError("nothing recorded: " + st->problem);
  for (const int j : sub.joints) {
    if (j < 0 || static_cast<std::size_t>(j) >= sub.skeleton.size()) {
      throw CommandError("nothing recorded: the server subscribed joint " + std::to_string(j) + " of a " +
                         std::to_string(sub.skeleton.size()) + "-joint skeleton");
    }
  }
  if (st->frames > 0 && st->values != sub.joints.size()) {
    throw CommandError("nothing recorded: frames of " + std::to_string(st->values) + " joints for a subscription of " +
                       std::to_string(sub.joints.size()));
  }
  if (st->frames == 0)
    throw CommandError("nothing recorded: the subscription ended (" + st->end_reason + ") before a frame");
  // Names and soft links from the view: each recorded joint hangs from its
  // nearest recorded ancestor.
  std::vector<std::string> names;
  std::vector<int> soft;
  for (int j : sub.joints) {
    names.push_back(sub.skeleton.joint(j).name);
    int a = sub.skeleton.joint(j).parent;
    int link = kNoParent;
    for (; a != kNoParent && link == kNoParent; a = sub.skeleton.joint(a).parent) {
      const auto it = std::find(sub.joints.begin(), sub.joints.end(), a);
      if (it != sub.joints.end() && it - sub.joints.begin() < static_cast<std::ptrdiff_t>(names.size()) - 1) {
        link = static_cast<int>(it - sub.joints.begin());
      }
    }
    soft.push_back(link);
  }
  const Motion m = take(
      motion_from_world_poses(names, soft, sub.rate_hz > 0 ? 1.0 / sub.rate_hz : 0.0, st->positions, st->orientations));
  check(save_motion(m, o.out));
  std::fprintf(
      stderr, "recorded %llu frames of %s (%zu joints) to %s: %s%s\n", static_cast<unsigned long long>(m.frame_count),
      shown(o.motion).c_str(), names.size(), o.out.c_str(), shown(st->end_reason).c_str(),
      st->filled > 0 ? (", " + std::to_string(st->filled) + " lost frames filled with the one before").c_str() : "");
}

// ---- gmr publish
struct PublishCommand {
  ServerOptions server;
  std::string file;
  std::string name;  // default: the file's stem
  std::string asf;
  double rate = 0.0;  // 0: the file's own
  bool loop = false;
  std::uint64_t count = 0;  // frames to publish; 0: the file once (or forever with --loop)
  bool record = false;
  bool markers = false;  // a marker file (.c3d, .trc) as labelled markers, solved by the server
  std::string model = "cmu41";
  double calibration_seconds = 2.0;
};

// Sends `total` frames (0: until stopped) one per `frame_time` on a
// drift-free clock, `send(k)` sending the k-th; a refused frame ends it.
// Returns the frames sent.
std::uint64_t play(client::Client& c, std::uint64_t total, double frame_time,
                   const std::function<Status(std::uint64_t)>& send) {
  const auto period =
      std::chrono::duration_cast<std::chrono::steady_clock::duration>(std::chrono::duration<double>(frame_time));
  const auto start = std::chrono::steady_clock::now();
  std::uint64_t sent = 0;
  for (; total == 0 || sent < total; ++sent) {
    std::this_thread::sleep_until(start + period * static_cast<std::int64_t>(sent));
    if (!c.connected())
      throw CommandError("the server closed the connection after " + std::to_string(sent) + " frames");
    if (auto s = send(sent); !s.ok()) {
      std::fprintf(stderr, "frame %llu not sent: %s\n", static_cast<unsigned long long>(sent),
                   shown(s.error().message).c_str());
    }
    for (const auto& e : c.take_errors()) throw CommandError("the server refused a frame: " + e);
  }
  return sent;
}

// Plays a marker file as labelled markers (docs/protocol.md, "Live markers"):
// the names and the model, then x, y, z per marker each period (a missing
// point is sent as missing), then Unpublish. The server calibrates on the
// first seconds and serves the solved skeleton from then on.
void run_publish_markers(const PublishCommand& o) {
  Warnings warnings;
  const MarkerTrajectories d = take(load_markers(o.file, &warnings));
  print_warnings(warnings);
  if (d.frame_count == 0) throw CommandError(o.file + ": no frames to publish");
  const double rate = o.rate > 0 ? o.rate : d.frame_rate > 0 ? d.frame_rate : 120.0;
  client::MarkerPublishOptions po;
  po.name = o.name.empty() ? std::filesystem::path(o.file).stem().string() : o.name;
  po.frame_time = 1.0 / rate;
  po.model = o.model;
  po.calibration_seconds = o.calibration_seconds;
  po.units = d.units.empty() ? "mm" : d.units;
  po.record = o.record;
  auto c = connect(o.server);
  const client::Publication publication = take(c->publish_markers(d.names, po));
  std::fprintf(stderr, "publishing %s as live markers '%s': %zu markers, model %s, %.2f Hz%s; served after %.3g s\n",
               o.file.c_str(), po.name.c_str(), d.marker_count(), po.model.c_str(), rate, o.loop ? ", looping" : "",
               po.calibration_seconds);
  const std::uint64_t total = o.loop ? o.count : o.count != 0 ? std::min(o.count, d.frame_count) : d.frame_count;
  const std::size_t row = d.marker_count() * 3;
  const std::uint64_t sent = play(*c, total, 1.0 / rate, [&](std::uint64_t k) {
    const std::size_t f = k % d.frame_count;
    return c->publish_marker_frame(publication.id, std::span<const double>(d.positions).subspan(f * row, row));
  });
  check(c->unpublish(publication.id));
  for (const auto& e : c->take_errors()) throw CommandError("the server refused a frame: " + e);
  std::fprintf(stderr, "published %llu marker frames of '%s'%s\n", static_cast<unsigned long long>(sent),
               po.name.c_str(),
               publication.recording.empty()
                   ? ""
                   : ("; the server records the solved skeleton to " + shown(publication.recording)).c_str());
}

// Plays a motion file as a live source: the skeleton (pre-rotation), then one
// frame per period on a drift-free clock, then Unpublish.
void run_publish(const PublishCommand& o) {
  if (o.markers) return run_publish_markers(o);
  if (is_marker_file(o.file)) {
    throw CommandError(o.file + ": a marker file is published as labelled markers: add --markers (and --model)");
  }
  LoadOptions lo;
  lo.asf = o.asf;
  Warnings warnings;
  Motion m;
  if (lower_extension(o.file) == ".csv") {
    // `gmr positions` output: an all-roots source, every joint a root
    // holding its world position (and orientation, with those columns). The
    // CSV holds no rate: --rate, or 120 Hz.
    const PositionsTable t = take(read_positions_csv(o.file));
    m = take(motion_from_world_poses(t.joints, std::vector<int>(t.joints.size(), kNoParent),
                                     o.rate > 0 ? 1.0 / o.rate : 1.0 / 120.0, t.positions, t.orientations));
  } else {
    m = take(load_motion(o.file, lo, &warnings));
  }
  print_warnings(warnings);
  if (m.convention != Convention::kPreRotation) m = take(to_pre_rotation(m));
  if (m.frame_count == 0) throw CommandError(o.file + ": no frames to publish");
  const double frame_time = o.rate > 0 ? 1.0 / o.rate : m.frame_time > 0 ? m.frame_time : 1.0 / 120.0;
  client::PublishOptions po;
  po.name = o.name.empty() ? std::filesystem::path(o.file).stem().string() : o.name;
  po.frame_time = frame_time;
  po.metres_per_unit = take(motion_metres_per_unit(o.file, lo));
  auto c = connect(o.server);
  po.record = o.record;
  const client::Publication publication = take(c->publish(m.skeleton, po));
  const std::uint32_t id = publication.id;
  std::fprintf(stderr, "publishing %s as live '%s': %zu joints, %zu channels, %.2f Hz%s\n", o.file.c_str(),
               po.name.c_str(), m.skeleton.size(), m.stride(), 1.0 / frame_time, o.loop ? ", looping" : "");
  // Without --loop the file is published once: --count can only stop it early.
  const std::uint64_t total = o.loop ? o.count : o.count != 0 ? std::min(o.count, m.frame_count) : m.frame_count;
  const std::uint64_t sent =
      play(*c, total, frame_time, [&](std::uint64_t k) { return c->publish_frame(id, m.frame(k % m.frame_count)); });
  check(c->unpublish(id));
  for (const auto& e : c->take_errors()) throw CommandError("the server refused a frame: " + e);
  std::fprintf(
      stderr, "published %llu frames of '%s'%s\n", static_cast<unsigned long long>(sent), po.name.c_str(),
      publication.recording.empty() ? "" : ("; the server records them to " + shown(publication.recording)).c_str());
}

// ---- gmr discover
struct DiscoverOptions {
  std::string group = "239.255.74.2";
  std::uint16_t port = 7501;
  double seconds = 2.0;
};

// What to tell a user who heard no beacon: where this machine routes the
// group (the interface listeners join it on), and that a server bound to
// loopback sends on the loopback interface, which is heard only where the
// group is routed on loopback too (docs/live.md, "What to bind").
std::string why_none_heard(in_addr group, const std::string& name) {
  const int fd = ::socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0);
  sockaddr_in to{};
  to.sin_family = AF_INET;
  to.sin_addr = group;
  to.sin_port = htons(9);
  std::string route;
  if (fd >= 0 && ::connect(fd, reinterpret_cast<sockaddr*>(&to), sizeof to) == 0) {
    sockaddr_in self{};
    socklen_t len = sizeof self;
    char address[INET_ADDRSTRLEN] = {};
    if (::getsockname(fd, reinterpret_cast<sockaddr*>(&self), &len) == 0) {
      ::inet_ntop(AF_INET, &self.sin_addr, address, sizeof address);
    }
    route = self.sin_addr.s_addr == htonl(INADDR_ANY)
                ? "this machine routes " + name + " on an interface with no address of its own (loopback)"
                : "this machine routes " + name + " through " + address + "'s interface";
  } else {
    route = "this machine has no route for " + name + " (" + std::strerror(errno) +
            "): add one, e.g. ip route add 224.0.0.0/4 dev eth0";
  }
  if (fd >= 0) ::close(fd);
  return "heard nothing: " + route +
         ". A server sends beacons from the interface of its --bind address: one bound to 127.0.0.1 (the default) "
         "is heard only where the group is routed on loopback; start it with --bind <a LAN address> or 0.0.0.0, "
         "and --discovery-group (docs/live.md, \"What to bind\").";
}

// Listens to the discovery group for beacons (docs/protocol.md, "Discovery")
// and prints each server heard once, in the order heard.
void run_discover(const DiscoverOptions& o) {
  in_addr group{};
  if (::inet_pton(AF_INET, o.group.c_str(), &group) != 1 || (ntohl(group.s_addr) >> 28) != 0xE) {
    throw CommandError("--group " + o.group + " is not an IPv4 multicast address (224.0.0.0/4)");
  }
  const int fd = ::socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0);
  if (fd < 0) throw CommandError(std::string("cannot open a UDP socket: ") + std::strerror(errno));
  struct Closer {
    int fd;
    ~Closer() { ::close(fd); }
  } closer{fd};
  const int yes = 1;
  ::setsockopt(fd, SOL_SOCKET, SO_REUSEADDR, &yes, sizeof yes);
  sockaddr_in any{};
  any.sin_family = AF_INET;
  any.sin_addr.s_addr = htonl(INADDR_ANY);
  any.sin_port = htons(o.port);
  if (::bind(fd, reinterpret_cast<sockaddr*>(&any), sizeof any) != 0) {
    throw CommandError("cannot listen on UDP port " + std::to_string(o.port) + ": " + std::strerror(errno));
  }
  ip_mreq join{};
  join.imr_multiaddr = group;
  join.imr_interface.s_addr = htonl(INADDR_ANY);
  if (::setsockopt(fd, IPPROTO_IP, IP_ADD_MEMBERSHIP, &join, sizeof join) != 0) {
    throw CommandError("cannot join " + o.group + ": " + std::strerror(errno) + " (is there a multicast route?)");
  }
  std::map<std::string, bool> seen;
  std::printf("%-22s %-24s %5s %5s %5s %7s %4s  %s\n", "address", "server", "udp", "http", "proto", "motions", "live",
              "notes");
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(o.seconds);
  std::array<char, 2048> buf{};
  for (;;) {
    const auto left =
        std::chrono::duration_cast<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now());
    if (left.count() <= 0) break;
    pollfd p{fd, POLLIN, 0};
    if (::poll(&p, 1, static_cast<int>(left.count())) <= 0) continue;
    sockaddr_in from{};
    socklen_t len = sizeof from;
    const ssize_t n = ::recvfrom(fd, buf.data(), buf.size(), 0, reinterpret_cast<sockaddr*>(&from), &len);
    if (n < 4 || std::string_view(buf.data(), 4) != "GMRB") continue;
    gmr::stream::v1::Beacon b;
    if (!b.ParseFromArray(buf.data() + 4, static_cast<int>(n - 4))) continue;
    char address[INET_ADDRSTRLEN] = {};
    ::inet_ntop(AF_INET, &from.sin_addr, address, sizeof address);
    const std::string where = std::string(address) + ":" + std::to_string(b.tcp_port());
    if (seen[where]) continue;
    seen[where] = true;
    std::string notes;
    if (b.tls()) notes += "tls ";
    if (!b.multicast_group().empty()) notes += "multicast " + shown(b.multicast_group().substr(0, 64));
    // A beacon is anyone's datagram: nothing in it reaches the terminal raw.
    std::printf("%-22s %-24s %5u %5u %5u %7u %4u  %s\n", where.c_str(), shown(b.server_name().substr(0, 24)).c_str(),
                b.udp_port(), b.http_port(), b.protocol_version(), b.motions(), b.live_sources(), notes.c_str());
    std::fflush(stdout);
  }
  std::fprintf(stderr, "%zu server%s heard on %s:%u in %.1f s\n", seen.size(), seen.size() == 1 ? "" : "s",
               o.group.c_str(), o.port, o.seconds);
  if (seen.empty()) std::fprintf(stderr, "%s\n", why_none_heard(group, o.group).c_str());
}

}  // namespace

void add_net_commands(CLI::App& app) {
  {
    auto o = std::make_shared<ServerOptions>();
    CLI::App* cmd = app.add_subcommand("ls", "List the motions a gmr-server serves");
    add_connect_options(*cmd, *o);
    cmd->callback([o] { run_ls(*o); });
  }
  {
    auto o = std::make_shared<ServerOptions>();
    auto motion = std::make_shared<std::string>();
    CLI::App* cmd = app.add_subcommand("skeleton", "Show a served motion's joints, offsets and channels");
    cmd->add_option("motion", *motion, "Motion name (see gmr ls)")->required();
    add_connect_options(*cmd, *o);
    cmd->callback([o, motion] { run_skeleton(*o, *motion); });
  }
  {
    auto o = std::make_shared<QueryOptions>();
    CLI::App* cmd = app.add_subcommand(
        "query",
        "Print a served motion's positions as CSV (frame,joint,x,y,z), like gmr positions, computed by the server");
    cmd->add_option("motion", o->motion, "Motion name (see gmr ls)")->required();
    cmd->add_option("--frames", o->frames, "Half-open frame range A:B (either side may be empty)")
        ->capture_default_str();
    add_view_options(*cmd, o->view);
    add_pose_options(*cmd, o->orientations, o->local_transforms);
    add_connect_options(*cmd, o->server);
    cmd->callback([o] { run_query(*o); });
  }
  {
    auto o = std::make_shared<StreamOptions>();
    CLI::App* cmd = app.add_subcommand("stream", "Subscribe to a served motion and print the frames as they arrive");
    add_play_options(*cmd, *o);
    cmd->add_flag("--summary", o->summary, "Print a live summary twice a second instead of CSV rows");
    add_pose_options(*cmd, o->orientations, o->local_transforms);
    cmd->callback([o] { run_stream(*o); });
  }
  {
    auto o = std::make_shared<RecordOptions>();
    CLI::App* cmd = app.add_subcommand(
        "record", "Record what a subscription receives (its view, its conventions) as a motion file (atomic write)");
    add_play_options(*cmd, *o);
    cmd->add_option("-o,--output", o->out, "Output file: .gmr, .gmrb or .bvh")->required();
    cmd->add_option("--seconds", o->seconds, "Stop after this many seconds (default: when the subscription ends)");
    cmd->footer(
        "Over UDP, a lost frame is filled with the one before it (and counted); with --loop, stop it "
        "with --seconds or --count.");
    cmd->callback([o] { run_record(*o); });
  }
  {
    auto o = std::make_shared<DiscoverOptions>();
    CLI::App* cmd = app.add_subcommand("discover", "List the gmr-servers that announce themselves on this network");
    cmd->add_option("--group", o->group, "The discovery multicast group (gmr-server --discovery-group)")
        ->capture_default_str();
    cmd->add_option("--port", o->port, "Its port (gmr-server --discovery-port)")->capture_default_str();
    cmd->add_option("--seconds", o->seconds, "How long to listen (servers announce every second)")
        ->capture_default_str()
        ->check(CLI::PositiveNumber);
    cmd->callback([o] { run_discover(*o); });
  }
  {
    auto o = std::make_shared<PublishCommand>();
    CLI::App* cmd = app.add_subcommand(
        "publish",
        "Play a motion file (BVH, ASF/AMC, .gmr, .gmrb, or the CSV of gmr positions) to a gmr-server as a live source; "
        "a marker file (.c3d, .trc) with --markers");
    cmd->add_option("file", o->file, "Motion file")->required()->check(CLI::ExistingFile);
    cmd->add_option("--name", o->name, "The live motion's name on the server (default: the file's stem)");
    cmd->add_option("--asf", o->asf, "Skeleton for an .amc file (default: the single .asf beside it)");
    cmd->add_option("--rate", o->rate, "Frames per second (default: the file's own; 120 for a CSV)")
        ->check(CLI::PositiveNumber);
    cmd->add_flag("--loop", o->loop, "Start over at the end, until stopped (or --count)");
    cmd->add_option("--count", o->count,
                    "Publish at most this many frames, then end (without --loop, at most the file's frames: it is "
                    "published once)");
    cmd->add_flag("--record", o->record, "Ask the server to record the source (into its --record-dir) as .gmrb");
    cmd->add_flag("--markers", o->markers,
                  "FILE is a marker file (.c3d, .trc): publish its labelled markers; the server solves them into "
                  "--model's skeleton (docs/markers.md, \"Frame by frame\")");
    cmd->add_option("--model", o->model, "With --markers: the built-in skeleton model")->capture_default_str();
    cmd->add_option("--calibration-seconds", o->calibration_seconds,
                    "With --markers: the first seconds the server calibrates the model on (it serves the source "
                    "after them)")
        ->capture_default_str()
        ->check(CLI::PositiveNumber);
    add_connect_options(*cmd, o->server);
    cmd->footer(
        "The server needs a 'publish' token (--token or GMR_TOKEN; docs/security.md). Subscribers see it "
        "in gmr ls as source 'live', and stream it with every view option.");
    cmd->callback([o] { run_publish(*o); });
  }
}

}  // namespace gmr::cli

#else

namespace gmr::cli {
void add_net_commands(CLI::App& app) { (void)app; }
}  // namespace gmr::cli

#endif
