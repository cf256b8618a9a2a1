// Connection's write side: replies and frames gathered into one write, tried
// at once on the non-blocking socket, the rest asynchronously (connection.h).
#include <algorithm>
#include <span>

#include "transport/connection.h"

namespace gmr::server {

void Connection::request_flush() {
  if (writing_ || stopped_) return;
  if (on_lane()) {
    flush();
    return;
  }
  // Once per wake of the lane: what else arrives meanwhile goes in the same
  // write. Only the control loop asks from off the lane.
  if (flush_posted_) return;
  flush_posted_ = true;
  flush_asked_ = Clock::now();
  auto self = shared_from_this();
  if (threads_ != nullptr) {
    threads_->defer(lane_, LaneTask{[](void* c) { static_cast<Connection*>(c)->deferred_flush(); }, this, self});
    return;
  }
  net::post(io_, [self] { self->deferred_flush(); });
}

void Connection::deferred_flush() {
  Lock lock(m_);
  flush_posted_ = false;
  flush();
}

void Connection::flush() {
  if (writing_ || stopped_ || !secured_) return;
  if (replies_.empty() && frames_.empty()) {
    if (close_after_flush_) stop("closed by the server");
    return;
  }
  // One gathered write: every waiting reply, then every waiting frame (its
  // own head, then the shared body).
  std::vector<net::const_buffer>& buffers = gather_;
  buffers.clear();
  hold_.clear();
  hold_heads_.clear();
  in_flight_bytes_ = 0;
  for (auto& r : replies_) {
    buffers.push_back(net::buffer(*r));
    in_flight_bytes_ += r->size();
    hold_.push_back(std::move(r));
  }
  replies_.clear();
  reply_bytes_ = 0;
  // Frames still within their subscriber's staleness bound, each its own
  // head then the shared body (the buffers are made once every head is in
  // hold_heads_, which no longer moves).
  const std::size_t first_frame = hold_.size();
  hold_heads_.reserve(frames_.count());
  // Every frame of this write is stamped with the same time: now.
  const std::int64_t now = now_ns();
  const Clock::time_point write_time = Clock::now();
  frames_.drain(write_time, counters_, [&](PendingFrame& f) {
    oldest_frame_in_flight_ = std::min(oldest_frame_in_flight_, f.pushed_at);
    f.head.set_write_stamp(now);
    hold_heads_.push_back(f.head);
    in_flight_bytes_ += hold_heads_.back().size() + f.body->size();
    hold_.push_back(std::move(f.body));
    ++counters_.frames_sent;
    counters_.frame_wait.add(write_time - f.made_at);
  });
  for (std::size_t i = first_frame, head = 0; i < hold_.size(); ++i, ++head) {
    buffers.push_back(net::buffer(hold_heads_[head].data(), hold_heads_[head].size()));
    buffers.push_back(net::buffer(*hold_[i]));
  }
  writing_frames_ = !hold_heads_.empty();
  if (!writing_frames_) oldest_frame_in_flight_ = Clock::time_point::max();
  if (buffers.empty()) {  // every waiting frame was stale
    account();
    if (close_after_flush_) stop("closed by the server");
    return;
  }
  writing_ = true;
  write_started_ = write_time;  // the same clock reading as the frames' waits
  if (socket_.tls()) {
    account();
    // TLS writes one buffer at a time: given in one piece, the bytes go out
    // in full records rather than one record (and one send) per buffer.
    tls_out_.clear();
    tls_out_.reserve(in_flight_bytes_);
    for (const auto& b : buffers) tls_out_.append(static_cast<const char*>(b.data()), b.size());
    buffers.assign(1, net::buffer(tls_out_));
    hold_.clear();  // the copy is what is in flight now
    hold_heads_.clear();
    write_rest(0);
    return;
  }
  // Tried at once, as one sendmsg (the socket is non-blocking): usually the
  // kernel takes it all, and the write completes here with no operation
  // queued, no handler to run later and nothing allocated. What it does not
  // take goes out asynchronously.
  boost::system::error_code ec;
  const std::size_t n = socket_.tcp().write_some(std::span<const net::const_buffer>(buffers), ec);
  if (ec == net::error::would_block || ec == net::error::try_again) ec = {};
  if (ec || n == in_flight_bytes_) {
    wrote_all(ec, n);  // and into the budget: nothing in flight
    return;
  }
  account();  // what is in flight, while the rest is written
  // The buffers the kernel took are done; the first it took part of is cut.
  std::size_t skip = n, first = 0;
  while (skip >= buffers[first].size()) skip -= buffers[first++].size();
  buffers[first] += skip;
  buffers.erase(buffers.begin(), buffers.begin() + static_cast<std::ptrdiff_t>(first));
  write_rest(n);
}

void Connection::write_rest(std::size_t already) {
  // A view of gather_, which stays put until the write completes: the write
  // copies the view, not the vector.
  const std::span<const net::const_buffer> rest(gather_);
  socket_.async_write(rest, [self = shared_from_this(), already](const boost::system::error_code& ec, std::size_t n) {
    Lock lock(self->m_);
    self->wrote_all(ec, already + n);
  });
}

void Connection::wrote_all(const boost::system::error_code& ec, std::size_t n) {
  writing_ = false;
  hold_.clear();
  hold_heads_.clear();
  if (tls_out_.capacity() > kBodyChunk) std::string().swap(tls_out_);
  in_flight_bytes_ = 0;
  account();
  if (ec) {
    counters_.bytes_sent += n;
    if (ec != net::error::operation_aborted) stop("write failed: " + ec.message());
    return;
  }
  wrote(n);
  resume_reading();
  flush();
}

}  // namespace gmr::server
