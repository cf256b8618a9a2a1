// FrameHead: the bytes a pushed frame carries for one subscriber before the
// body every subscriber of the stream shares (frames.h: frame_head_for), in
// place. A head is made per frame and subscriber, so it costs no allocation;
// this header is light, for the server's outboxes.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <string_view>

namespace gmr::wire {

// Frame.server_write_time_ns as it ends a frame's head: its tag and 8 bytes.
inline constexpr std::size_t kWriteStampBytes = 9;
// Overwrites the stamp's value: the 8 bytes at `value`.
void set_write_stamp(char* value, std::int64_t ns);

// The bytes that go before a shared body to make it a whole ServerMessage
// (frame_head_for), held in place: a head is made per frame and subscriber,
// and allocating each would cost more than writing it.
class FrameHead {
 public:
  // At most 4 (length prefix) + 2 + 10 (ServerMessage.frame's tag, length)
  // + 23 (three ids) + 9 (the stamp).
  static constexpr std::size_t kCapacity = 48;

  const char* data() const { return bytes_.data(); }
  std::size_t size() const { return size_; }
  std::string_view view() const { return {bytes_.data(), size_}; }
  // Its last kWriteStampBytes are the write stamp.
  void set_write_stamp(std::int64_t ns) { wire::set_write_stamp(bytes_.data() + size_ - 8, ns); }

 private:
  friend FrameHead frame_head_for(std::uint32_t, std::uint32_t, std::uint64_t, std::size_t, bool);
  std::array<char, kCapacity> bytes_;
  std::uint8_t size_ = 0;
};

// The head before a shared body of `body_size` bytes (with the TCP length
// prefix when `length_prefix`): lengths, ids, and a write stamp of 0 as its
// last kWriteStampBytes.
FrameHead frame_head_for(std::uint32_t view_id, std::uint32_t subscription_id, std::uint64_t stream_id,
                         std::size_t body_size, bool length_prefix);

}  // namespace gmr::wire
