#include "gmr/io/gmrb.h"

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <bit>
#include <cerrno>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>

#include "gmr/core/file_util.h"
#include "gmr/core/limits.h"

namespace gmr {
namespace {

constexpr char kMagic[8] = {'G', 'M', 'R', 'B', '\r', '\n', '\x1a', '\n'};
constexpr std::uint32_t kByteOrderMark = 0x01020304u;
constexpr std::size_t kHeaderSize = 64;
constexpr std::size_t kDataAlignment = 64;
constexpr std::size_t kMaxNameLength = 4096;
// Smallest joint record: name length, a 1-byte name, parent, soft parent,
// offset, channel count.
constexpr std::size_t kMinJointRecord = 4 + 1 + 4 + 4 + 24 + 1;

template <class T>
T byteswap(T v) {
  unsigned char b[sizeof(T)];
  std::memcpy(b, &v, sizeof(T));
  for (std::size_t i = 0; i < sizeof(T) / 2; ++i) std::swap(b[i], b[sizeof(T) - 1 - i]);
  std::memcpy(&v, b, sizeof(T));
  return v;
}

// Little-endian on disk, whatever the host.
template <class T>
T from_le(T v) {
  if constexpr (std::endian::native == std::endian::big) return byteswap(v);
  return v;
}

std::size_t round_up(std::size_t n, std::size_t m) { return (n + m - 1) / m * m; }

// Reads fixed-size fields from a byte range, failing past its end.
class Reader {
 public:
  Reader(std::string_view bytes, std::size_t base) : bytes_(bytes), base_(base) {}
  template <class T>
  bool get(T& out) {
    if (bytes_.size() - pos_ < sizeof(T)) return false;
    std::memcpy(&out, bytes_.data() + pos_, sizeof(T));
    out = from_le(out);
    pos_ += sizeof(T);
    return true;
  }
  bool get_string(std::size_t n, std::string& out) {
    if (bytes_.size() - pos_ < n) return false;
    out.assign(bytes_.data() + pos_, n);
    pos_ += n;
    return true;
  }
  std::size_t offset() const { return base_ + pos_; }
  std::size_t left() const { return bytes_.size() - pos_; }

 private:
  std::string_view bytes_;
  std::size_t base_;
  std::size_t pos_ = 0;
};

struct Header {
  Convention convention = Convention::kPreRotation;
  std::uint64_t joints = 0;
  std::uint64_t channels = 0;
  std::uint64_t frames = 0;
  double frame_time = 0;
  std::uint64_t skeleton_bytes = 0;
  std::size_t data_offset = 0;
};

// Checks the header against the file size: everything it announces must be
// there, exactly, before anything is allocated.
Result<Header> parse_header(std::string_view head, std::uint64_t file_size, std::string_view label) {
  if (head.size() < kHeaderSize) {
    return byte_error(label, head.size(),
                      "file too short for a .gmrb header (" + std::to_string(head.size()) + " of 64 bytes)");
  }
  if (std::memcmp(head.data(), kMagic, sizeof kMagic) != 0) return byte_error(label, 0, "not a .gmrb file (bad magic)");
  Reader r(head.substr(8, kHeaderSize - 8), 8);
  std::uint32_t version = 0, bom = 0, header_size = 0, convention = 0;
  Header h;
  r.get(version);
  r.get(bom);
  r.get(header_size);
  r.get(convention);
  r.get(h.joints);
  r.get(h.channels);
  r.get(h.frames);
  r.get(h.frame_time);
  r.get(h.skeleton_bytes);
  if (version != kGmrbVersion) {
    return byte_error(label, 8,
                      "unsupported .gmrb version " + std::to_string(version) + " (this build reads version " +
                          std::to_string(kGmrbVersion) + ")");
  }
  if (bom != kByteOrderMark) return byte_error(label, 12, "bad byte-order mark (expected 0x01020304 little-endian)");
  if (header_size != kHeaderSize)
    return byte_error(label, 16, "header size " + std::to_string(header_size) + ", expected 64");
  if (convention > 1)
    return byte_error(label, 20, "convention " + std::to_string(convention) + ", expected 0 (GMR) or 1 (BVH)");
  h.convention = convention == 0 ? Convention::kPreRotation : Convention::kPostRotation;
  if (!std::isfinite(h.frame_time) || h.frame_time < 0)
    return byte_error(label, 48, "frame time must be finite and >= 0");
  const std::uint64_t after_header = file_size - kHeaderSize;
  if (h.skeleton_bytes > after_header) {
    return byte_error(label, 56,
                      "skeleton of " + std::to_string(h.skeleton_bytes) + " bytes, but only " +
                          std::to_string(after_header) + " bytes follow the header");
  }
  if (h.joints > h.skeleton_bytes / kMinJointRecord) {
    return byte_error(label, 24,
                      std::to_string(h.joints) + " joints cannot fit in a skeleton of " +
                          std::to_string(h.skeleton_bytes) + " bytes");
  }
  if (h.channels > h.joints * 6) {
    return byte_error(
        label, 32,
        std::to_string(h.channels) + " channels for " + std::to_string(h.joints) + " joints (at most 6 each)");
  }
  h.data_offset = round_up(kHeaderSize + h.skeleton_bytes, kDataAlignment);
  const std::uint64_t data_bytes = file_size >= h.data_offset ? file_size - h.data_offset : 0;
  if (file_size < h.data_offset) {
    return byte_error(label, file_size,
                      "file ends before the channel data (expected it at byte " + std::to_string(h.data_offset) + ")");
  }
  // frames * channels * 8 == data_bytes, without overflow.
  if (h.channels == 0 ? data_bytes != 0
                      : (data_bytes % (h.channels * 8) != 0 || data_bytes / (h.channels * 8) != h.frames)) {
    const std::uint64_t have = h.channels == 0 ? 0 : data_bytes / (h.channels * 8);
    return byte_error(label, 40,
                      "header announces " + std::to_string(h.frames) + " frames of " + std::to_string(h.channels) +
                          " channels, but the file holds " + std::to_string(data_bytes) + " data bytes (" +
                          std::to_string(have) + " whole frames): truncated or corrupt");
  }
  if (auto s = check_frame_count(h.frames, h.channels * 8, data_bytes); !s.ok())
    return byte_error(label, 40, s.error().message);
  return h;
}

Result<Skeleton> parse_skeleton(std::string_view bytes, const Header& h, std::string_view label) {
  Reader r(bytes, kHeaderSize);
  std::vector<Joint> joints;
  joints.reserve(static_cast<std::size_t>(h.joints));
  std::uint64_t channels = 0;
  for (std::uint64_t j = 0; j < h.joints; ++j) {
    const std::size_t start = r.offset();
    const auto truncated = [&] {
      return byte_error(label, r.offset(), "skeleton section ends inside joint " + std::to_string(j));
    };
    Joint joint;
    std::uint32_t name_length = 0;
    if (!r.get(name_length)) return truncated();
    if (name_length == 0 || name_length > kMaxNameLength) {
      return byte_error(
          label, start,
          "joint " + std::to_string(j) + " name length " + std::to_string(name_length) + " (expected 1 to 4096)");
    }
    if (!r.get_string(name_length, joint.name)) return truncated();
    std::int32_t parent = 0, soft = 0;
    if (!r.get(parent) || !r.get(soft)) return truncated();
    joint.parent = parent;
    joint.soft_parent = soft;
    for (int a = 0; a < 3; ++a) {
      double v = 0;
      if (!r.get(v)) return truncated();
      if (!std::isfinite(v)) return byte_error(label, r.offset() - 8, "joint " + joint.name + " offset is not finite");
      joint.offset[a] = v;
    }
    std::uint8_t count = 0;
    if (!r.get(count)) return truncated();
    if (count > 6)
      return byte_error(label, r.offset() - 1,
                        "joint " + joint.name + " has " + std::to_string(count) + " channels (at most 6)");
    for (std::uint8_t i = 0; i < count; ++i) {
      std::uint8_t c = 0;
      if (!r.get(c)) return truncated();
      if (c > 5)
        return byte_error(label, r.offset() - 1, "joint " + joint.name + ": unknown channel code " + std::to_string(c));
      joint.channels.push_back(static_cast<ChannelType>(c));
    }
    channels += count;
    joints.push_back(std::move(joint));
  }
  if (r.left() != 0) {
    return byte_error(label, r.offset(), std::to_string(r.left()) + " unused bytes at the end of the skeleton section");
  }
  if (channels != h.channels) {
    return byte_error(label, 32,
                      "header announces " + std::to_string(h.channels) + " channels per frame, the joints list " +
                          std::to_string(channels));
  }
  auto skeleton = Skeleton::create(std::move(joints));
  if (!skeleton) return byte_error(label, kHeaderSize, "invalid skeleton: " + skeleton.error().message);
  return skeleton;
}

// Decodes the little-endian doubles in place and checks they are finite.
// The check runs on blocks with integer operations the compiler vectorizes:
// a double is not finite when its 11 exponent bits are all ones, and then
// adding one to the exponent field carries into the sign bit. Only a block
// that has one is searched for the first bad value.
Status finish_values(std::vector<double>& values, std::size_t channels, std::size_t data_offset,
                     std::string_view label) {
  if constexpr (std::endian::native == std::endian::big) {
    for (double& v : values) v = byteswap(v);
  }
  constexpr std::uint64_t kExponent = 0x7FF0000000000000u;
  constexpr std::uint64_t kExponentOne = 0x0010000000000000u;
  constexpr std::size_t kBlock = 4096;
  for (std::size_t b = 0; b < values.size(); b += kBlock) {
    const std::size_t e = std::min(values.size(), b + kBlock);
    std::uint64_t carry = 0;
    for (std::size_t i = b; i < e; ++i) carry |= (std::bit_cast<std::uint64_t>(values[i]) & kExponent) + kExponentOne;
    if ((carry >> 63) == 0) continue;
    for (std::size_t i = b; i < e; ++i) {
      if (!std::isfinite(values[i])) {
        return byte_error(
            label, data_offset + i * 8,
            "value " + std::to_string(i % channels) + " of frame " + std::to_string(i / channels) + " is not finite");
      }
    }
  }
  return Ok{};
}

// Sizes `values` for n doubles. A large fresh buffer is asked to use huge
// pages before it is first touched: on this VM a 4 KiB page fault costs
// microseconds, which for a 160 MB motion is most of the load time.
void size_values(std::vector<double>& values, std::size_t n) {
  values.reserve(n);
#if defined(__linux__) && defined(MADV_HUGEPAGE)
  constexpr std::uintptr_t kHuge = std::uintptr_t{2} << 20;
  const auto begin = reinterpret_cast<std::uintptr_t>(values.data());
  const std::uintptr_t first = (begin + kHuge - 1) & ~(kHuge - 1);
  const std::uintptr_t end = begin + n * sizeof(double);
  if (n * sizeof(double) >= 8 * kHuge && end > first) {
    ::madvise(reinterpret_cast<void*>(first), (end - first) & ~(kHuge - 1), MADV_HUGEPAGE);  // a hint: failure is fine
  }
#endif
  values.resize(n);
}

Motion make_motion(Skeleton skeleton, const Header& h) {
  Motion m;
  m.skeleton = std::move(skeleton);
  m.convention = h.convention;
  m.frame_time = h.frame_time;
  m.frame_count = static_cast<std::size_t>(h.frames);
  return m;
}

template <class T>
void put(std::string& out, T v) {
  v = from_le(v);
  out.append(reinterpret_cast<const char*>(&v), sizeof v);
}

Error file_error(const std::filesystem::path& path, std::string_view what, int err) {
  Error e;
  e.file = path.string();
  e.message = std::string(what) + ": " + std::strerror(err);
  return e;
}

// Reads exactly n bytes (or up to EOF: returns how many were read).
Result<std::size_t> read_fully(int fd, char* dst, std::size_t n, const std::filesystem::path& path) {
  std::size_t got = 0;
  while (got < n) {
    const ssize_t k = ::read(fd, dst + got, n - got);
    if (k < 0) {
      if (errno == EINTR) continue;
      return file_error(path, "cannot read file", errno);
    }
    if (k == 0) break;
    got += static_cast<std::size_t>(k);
  }
  return got;
}

}  // namespace

Result<Motion> parse_gmrb(std::string_view bytes, std::string_view file_label) {
  auto h = parse_header(bytes.substr(0, std::min(bytes.size(), kHeaderSize)), bytes.size(), file_label);
  if (!h) return h.error();
  auto skeleton =
      parse_skeleton(bytes.substr(kHeaderSize, static_cast<std::size_t>(h->skeleton_bytes)), *h, file_label);
  if (!skeleton) return skeleton.error();
  Motion m = make_motion(std::move(*skeleton), *h);
  size_values(m.values, m.frame_count * m.stride());
  if (!m.values.empty()) std::memcpy(m.values.data(), bytes.data() + h->data_offset, m.values.size() * sizeof(double));
  if (Status s = finish_values(m.values, m.stride(), h->data_offset, file_label); !s) return s.error();
  return m;
}

Result<Motion> read_gmrb(const std::filesystem::path& path) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return file_error(path, "cannot open file", errno);
  struct Closer {
    int fd;
    ~Closer() { ::close(fd); }
  } closer{fd};
  struct stat st {};
  if (::fstat(fd, &st) != 0) return file_error(path, "cannot stat file", errno);
  if (!S_ISREG(st.st_mode)) return file_error(path, "cannot read file", S_ISDIR(st.st_mode) ? EISDIR : EINVAL);
  const std::uint64_t size = static_cast<std::uint64_t>(st.st_size);
  const std::string label = path.string();

  char head[kHeaderSize];
  auto got = read_fully(fd, head, kHeaderSize, path);
  if (!got) return got.error();
  auto h = parse_header(std::string_view(head, *got), size, label);
  if (!h) return h.error();
  // The header checked skeleton_bytes against the file size: this allocation
  // is bounded by the file.
  std::string skel(static_cast<std::size_t>(h->data_offset - kHeaderSize), '\0');
  got = read_fully(fd, skel.data(), skel.size(), path);
  if (!got) return got.error();
  if (*got != skel.size()) return byte_error(label, kHeaderSize + *got, "file ends inside the skeleton section");
  auto skeleton =
      parse_skeleton(std::string_view(skel).substr(0, static_cast<std::size_t>(h->skeleton_bytes)), *h, label);
  if (!skeleton) return skeleton.error();
  Motion m = make_motion(std::move(*skeleton), *h);
  size_values(m.values, m.frame_count * m.stride());
  const std::size_t data_bytes = m.values.size() * sizeof(double);
  got = read_fully(fd, reinterpret_cast<char*>(m.values.data()), data_bytes, path);
  if (!got) return got.error();
  if (*got != data_bytes)
    return byte_error(label, h->data_offset + *got, "file ends inside the channel data (it shrank while read)");
  if (Status s = finish_values(m.values, m.stride(), h->data_offset, label); !s) return s.error();
  return m;
}

Result<std::string> format_gmrb(const Motion& motion) {
  if (Status s = motion.validate(); !s) return s.error();
  const Skeleton& sk = motion.skeleton;
  std::string skel;
  for (const Joint& j : sk.joints()) {
    if (j.name.size() > kMaxNameLength)
      return make_error("joint name longer than 4096 bytes: " + j.name.substr(0, 40) + "...");
    put(skel, static_cast<std::uint32_t>(j.name.size()));
    skel += j.name;
    put(skel, static_cast<std::int32_t>(j.parent));
    put(skel, static_cast<std::int32_t>(j.soft_parent));
    for (int a = 0; a < 3; ++a) put(skel, j.offset[a]);
    put(skel, static_cast<std::uint8_t>(j.channels.size()));
    for (ChannelType c : j.channels) put(skel, static_cast<std::uint8_t>(c));
  }
  std::string out;
  const std::size_t data_offset = round_up(kHeaderSize + skel.size(), kDataAlignment);
  out.reserve(data_offset + motion.values.size() * sizeof(double));
  out.append(kMagic, sizeof kMagic);
  put(out, kGmrbVersion);
  put(out, kByteOrderMark);
  put(out, static_cast<std::uint32_t>(kHeaderSize));
  put(out, static_cast<std::uint32_t>(motion.convention == Convention::kPreRotation ? 0 : 1));
  put(out, static_cast<std::uint64_t>(sk.size()));
  put(out, static_cast<std::uint64_t>(sk.channel_count()));
  put(out, static_cast<std::uint64_t>(motion.frame_count));
  put(out, motion.frame_time);
  put(out, static_cast<std::uint64_t>(skel.size()));
  out += skel;
  out.resize(data_offset, '\0');
  if constexpr (std::endian::native == std::endian::little) {
    if (!motion.values.empty())
      out.append(reinterpret_cast<const char*>(motion.values.data()), motion.values.size() * sizeof(double));
  } else {
    for (double v : motion.values) put(out, v);
  }
  return out;
}

Result<GmrbAppender> GmrbAppender::open(const Motion& pattern, const std::filesystem::path& path) {
  Motion head;
  head.skeleton = pattern.skeleton;
  head.convention = pattern.convention;
  head.frame_time = pattern.frame_time;
  head.frame_count = 0;
  auto bytes = format_gmrb(head);
  if (!bytes) {
    Error e = bytes.error();
    if (e.file.empty()) e.file = path.string();
    return e;
  }
  auto file = AtomicFileWriter::open(path, *bytes);
  if (!file) return file.error();
  return GmrbAppender(std::move(file).value(), static_cast<std::size_t>(head.skeleton.channel_count()));
}

Status GmrbAppender::append(std::span<const double> frame) {
  if (frame.size() != stride_) {
    return make_error("a frame of " + std::to_string(frame.size()) + " values; the skeleton has " +
                      std::to_string(stride_) + " channels");
  }
  std::string out;
  if constexpr (std::endian::native == std::endian::little) {
    out.assign(reinterpret_cast<const char*>(frame.data()), frame.size() * sizeof(double));
  } else {
    for (double v : frame) put(out, v);
  }
  if (Status s = file_.append(out); !s) return s;
  ++frames_;
  return Ok{};
}

Result<std::uint64_t> GmrbAppender::finish() {
  // The frame count: after magic, version, byte-order mark, header size,
  // convention, joint count and channel count (format_gmrb's order).
  constexpr std::size_t kFrameCountOffset = sizeof kMagic + 4 + 4 + 4 + 4 + 8 + 8;
  std::string count;
  put(count, frames_);
  if (Status s = file_.patch(kFrameCountOffset, count); !s) return s.error();
  const std::uint64_t size = file_.size();
  if (Status s = file_.commit(); !s) return s.error();
  return size;
}

Status write_gmrb(const Motion& motion, const std::filesystem::path& path) {
  auto bytes = format_gmrb(motion);
  if (!bytes) {
    Error e = bytes.error();
    if (e.file.empty()) e.file = path.string();
    return e;
  }
  return write_file_atomic(path, *bytes);
}

}  // namespace gmr
