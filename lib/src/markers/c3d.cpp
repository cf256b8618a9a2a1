// C3D reader: header, parameter section, 3D point data. Analog samples are
// skipped (their size is needed to step from frame to frame).
//
//   block 1        header: 16-bit words (parameter block, points, analog
//                  values per frame, first/last frame, scale, data block, rate)
//   block P        parameter header (byte 4: processor 84 Intel, 85 DEC,
//                  86 MIPS), then group and parameter records, each giving the
//                  offset of the next
//   block D ...    frames: points x (x, y, z, residual word), then analog
//                  values; int16 or float (negative POINT:SCALE)
#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <iterator>
#include <limits>
#include <map>
#include <optional>
#include <string_view>

#include "gmr/core/file_util.h"
#include "gmr/core/limits.h"
#include "gmr/markers/c3d.h"
#include "names.h"

namespace gmr {
namespace {

constexpr std::size_t kBlock = 512;
constexpr std::size_t kMaxDims = 7;
// Frame counts beyond this are not believed even when the file could hold them
// (a corrupt parameter); 2^28 frames is 25 days at 120 Hz.
constexpr std::size_t kMaxPoints = 65535;

enum class Processor { kIntel, kDec, kMips };

// Number decoding for one processor type. Offsets are checked by the caller.
struct Decoder {
  Processor processor = Processor::kIntel;
  std::string_view bytes;

  std::uint16_t u16(std::size_t at) const {
    const auto* b = reinterpret_cast<const unsigned char*>(bytes.data() + at);
    return processor == Processor::kMips ? static_cast<std::uint16_t>(b[0] << 8 | b[1])
                                         : static_cast<std::uint16_t>(b[1] << 8 | b[0]);
  }
  std::int16_t i16(std::size_t at) const { return static_cast<std::int16_t>(u16(at)); }
  double f32(std::size_t at) const {
    const auto* b = reinterpret_cast<const unsigned char*>(bytes.data() + at);
    if (processor == Processor::kDec) {
      // VAX F-float: two little-endian 16-bit words, the first holding sign,
      // 8-bit exponent (bias 128) and the top mantissa bits; the value is
      // 0.1mmm (binary) x 2^(e-128) = 1.mmm x 2^(e-129). Exponent 0 is zero
      // (or, with the sign set, a reserved operand: NaN).
      const std::uint32_t bits =
          std::uint32_t{b[1]} << 24 | std::uint32_t{b[0]} << 16 | std::uint32_t{b[3]} << 8 | b[2];
      const int e = static_cast<int>((bits >> 23) & 0xff);
      const bool negative = (bits >> 31) != 0;
      if (e == 0) return negative ? std::numeric_limits<double>::quiet_NaN() : 0.0;
      const double m = 1.0 + static_cast<double>(bits & 0x7fffff) / 8388608.0;
      const double v = std::ldexp(m, e - 129);
      return negative ? -v : v;
    }
    std::uint32_t bits =
        processor == Processor::kMips
            ? (std::uint32_t{b[0]} << 24 | std::uint32_t{b[1]} << 16 | std::uint32_t{b[2]} << 8 | b[3])
            : (std::uint32_t{b[3]} << 24 | std::uint32_t{b[2]} << 16 | std::uint32_t{b[1]} << 8 | b[0]);
    float f;
    std::memcpy(&f, &bits, 4);
    return f;
  }
};

// One parameter record: its type (-1 char, 1 byte, 2 int16, 4 float), its
// dimensions (Fortran order: the first varies fastest) and where its data is.
struct Parameter {
  int type = 0;
  std::vector<std::size_t> dims;
  std::size_t data = 0;   // byte offset of the first element
  std::size_t count = 0;  // elements
  std::size_t record = 0;
};

std::string upper(std::string s) {
  for (char& c : s) c = static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
  return s;
}

std::string trim(std::string_view s) {
  const auto is_pad = [](char c) { return c == ' ' || c == '\0' || c == '\t' || c == '\r' || c == '\n'; };
  std::size_t b = 0, e = s.size();
  while (b < e && is_pad(s[b])) ++b;
  while (e > b && is_pad(s[e - 1])) --e;
  return std::string(s.substr(b, e - b));
}

class C3dReader {
 public:
  C3dReader(std::string_view bytes, std::string_view label, Warnings* warnings)
      : bytes_(bytes), label_(label), warnings_(warnings) {}

  Result<MarkerTrajectories> read();

 private:
  void warn(std::size_t offset, std::string message) {
    if (warnings_) warnings_->push_back(byte_error(label_, offset, std::move(message)));
  }
  std::optional<Status> read_parameters(std::size_t start);
  const Parameter* find(const std::string& group, const std::string& name) const {
    const auto it = params_.find(group + ":" + name);
    return it == params_.end() ? nullptr : &it->second;
  }
  // First element of a numeric parameter as a double (int16 read signed
  // unless `unsigned16`), or nothing when absent or not numeric.
  std::optional<double> number(const std::string& group, const std::string& name, std::size_t i = 0,
                               bool unsigned16 = false) const {
    const Parameter* p = find(group, name);
    if (!p || i >= p->count) return std::nullopt;
    switch (p->type) {
      case 1:
        return static_cast<double>(static_cast<unsigned char>(bytes_[p->data + i]));
      case 2:
        return unsigned16 ? dec_.u16(p->data + 2 * i) : dec_.i16(p->data + 2 * i);
      case 4:
        return dec_.f32(p->data + 4 * i);
      default:
        return std::nullopt;
    }
  }
  // A count (int16 read unsigned, byte, or float): nothing unless it is a
  // whole number from 0 to 2^31 (a corrupt float must not reach a cast).
  std::optional<std::size_t> count(const std::string& group, const std::string& name) const {
    const auto v = number(group, name, 0, true);
    if (!v || !(*v >= 0 && *v <= 2147483648.0)) return std::nullopt;
    return static_cast<std::size_t>(*v);
  }
  // Strings of a char parameter: dims[0] characters each, trimmed.
  std::vector<std::string> strings(const std::string& group, const std::string& name) const {
    std::vector<std::string> out;
    const Parameter* p = find(group, name);
    if (!p || p->type != -1) return out;
    if (p->dims.empty()) {
      out.push_back(trim(bytes_.substr(p->data, 1)));
      return out;
    }
    const std::size_t len = p->dims[0];
    if (len == 0) return out;
    for (std::size_t at = 0; at + len <= p->count; at += len) out.push_back(trim(bytes_.substr(p->data + at, len)));
    return out;
  }

  std::string_view bytes_;
  std::string_view label_;
  Warnings* warnings_;
  Decoder dec_;
  std::map<std::string, Parameter> params_;  // "GROUP:NAME", upper case
};

// Reads every record of the parameter section. Records are chained by their
// "offset to next" field; the chain ends at offset 0, a zero name length, or
// the end of the file. Groups are named before or after their parameters, so
// parameters are keyed by group id first and named at the end.
std::optional<Status> C3dReader::read_parameters(std::size_t start) {
  struct Raw {
    int group;
    std::string name;
    Parameter p;
  };
  std::vector<Raw> raw;
  std::map<int, std::string> groups;
  std::size_t pos = start + 4;
  const std::size_t end = bytes_.size();
  while (true) {
    if (pos + 2 > end) break;  // runs into the end of the file: treat as the last record
    const auto name_length = static_cast<std::int8_t>(bytes_[pos]);
    const auto id = static_cast<std::int8_t>(bytes_[pos + 1]);
    if (name_length == 0 || id == 0) break;
    const std::size_t n = static_cast<std::size_t>(name_length < 0 ? -name_length : name_length);
    const std::size_t record = pos;
    if (pos + 2 + n + 2 > end)
      return Status(byte_error(label_, record, "parameter record runs past the end of the file"));
    std::string name = upper(trim(bytes_.substr(pos + 2, n)));
    const std::size_t next_field = pos + 2 + n;
    const std::int16_t next = dec_.i16(next_field);
    std::size_t q = next_field + 2;
    if (id < 0) {
      groups[-id] = name;
    } else {
      if (q + 2 > end) return Status(byte_error(label_, q, "parameter " + name + " ends at the end of the file"));
      Parameter p;
      p.record = record;
      p.type = static_cast<std::int8_t>(bytes_[q]);
      const std::size_t ndims = static_cast<unsigned char>(bytes_[q + 1]);
      if (p.type != -1 && p.type != 1 && p.type != 2 && p.type != 4) {
        return Status(byte_error(
            label_, q, "parameter " + name + " has type " + std::to_string(p.type) + " (expected -1, 1, 2 or 4)"));
      }
      if (ndims > kMaxDims) {
        return Status(byte_error(label_, q + 1,
                                 "parameter " + name + " has " + std::to_string(ndims) + " dimensions (at most 7)"));
      }
      q += 2;
      if (q + ndims > end)
        return Status(byte_error(label_, q, "parameter " + name + " dimensions run past the end of the file"));
      std::size_t count = 1;
      for (std::size_t d = 0; d < ndims; ++d) {
        p.dims.push_back(static_cast<unsigned char>(bytes_[q + d]));
        count *= p.dims.back();  // at most 255^7 < 2^56: no overflow
      }
      q += ndims;
      const std::size_t size = static_cast<std::size_t>(p.type < 0 ? -p.type : p.type);
      if (count > (end - q) / size) {
        return Status(byte_error(label_, q,
                                 "parameter " + name + " holds " + std::to_string(count) + " values of " +
                                     std::to_string(size) + " bytes, past the end of the file"));
      }
      p.data = q;
      p.count = count;
      raw.push_back({id, std::move(name), std::move(p)});
    }
    if (next <= 0) break;  // 0: last record; negative: no way forward
    pos = next_field + static_cast<std::size_t>(next);
  }
  for (Raw& r : raw) {
    const auto g = groups.find(r.group);
    if (g == groups.end()) continue;  // a parameter of no known group: unreachable by name
    params_.emplace(g->second + ":" + r.name, std::move(r.p));
  }
  return std::nullopt;
}

Result<MarkerTrajectories> C3dReader::read() {
  if (bytes_.size() < kBlock) {
    return byte_error(label_, bytes_.size(),
                      "file too short for a C3D header (" + std::to_string(bytes_.size()) + " of 512 bytes)");
  }
  const std::size_t param_block = static_cast<unsigned char>(bytes_[0]);
  if (static_cast<unsigned char>(bytes_[1]) != 0x50) {
    return byte_error(
        label_, 1,
        "not a C3D file (byte 2 is " + std::to_string(static_cast<unsigned char>(bytes_[1])) + ", expected 80)");
  }
  if (param_block == 0) return byte_error(label_, 0, "parameter section at block 0 (blocks count from 1)");
  const std::size_t param_start = (param_block - 1) * kBlock;
  if (param_start + 4 > bytes_.size()) {
    return byte_error(label_, 0,
                      "parameter section at block " + std::to_string(param_block) + " (byte " +
                          std::to_string(param_start) + ") is past the end of the file (" +
                          std::to_string(bytes_.size()) + " bytes)");
  }
  const int processor = static_cast<unsigned char>(bytes_[param_start + 3]);
  switch (processor) {
    case 84:
      dec_.processor = Processor::kIntel;
      break;
    case 85:
      dec_.processor = Processor::kDec;
      break;
    case 86:
      dec_.processor = Processor::kMips;
      break;
    default:
      return byte_error(
          label_, param_start + 3,
          "unknown processor type " + std::to_string(processor) + " (expected 84 Intel, 85 DEC or 86 MIPS)");
  }
  dec_.bytes = bytes_;
  if (auto s = read_parameters(param_start)) return s->error();

  // Header words (1-based word n at byte 2(n-1)).
  const auto word = [&](int n) { return dec_.u16(static_cast<std::size_t>(2 * (n - 1))); };
  const std::size_t header_points = word(2);
  const std::size_t header_analog = word(3);
  const std::size_t header_first = word(4);
  const std::size_t header_last = word(5);
  const double header_scale = dec_.f32(12);
  const std::size_t header_data_block = word(9);
  const double header_rate = dec_.f32(20);

  MarkerTrajectories out;
  // Points.
  std::size_t points = header_points;
  if (auto used = count("POINT", "USED")) {
    if (*used != header_points) {
      warn(2, "header says " + std::to_string(header_points) + " points, POINT:USED " + std::to_string(*used) +
                  ": using POINT:USED");
    }
    points = *used;
  }
  if (points > kMaxPoints) return byte_error(label_, 2, "implausible point count " + std::to_string(points));

  // Scale: negative means float storage; its magnitude scales integers and residuals.
  double scale = header_scale;
  if (auto s = number("POINT", "SCALE")) scale = *s;
  if (!std::isfinite(scale)) return byte_error(label_, 12, "POINT:SCALE is not a finite number");
  const bool floats = scale < 0;
  const double abs_scale = std::fabs(scale);
  const std::size_t value_size = floats ? 4 : 2;

  // Frame rate.
  double rate = header_rate;
  if (auto r = number("POINT", "RATE")) rate = *r;
  if (!std::isfinite(rate) || rate < 0 || (rate > 0 && rate < 1e-3) || rate > 1e6) {
    warn(20, "frame rate " + format_double(rate) + " Hz is not usable: set to 0 (unknown)");
    rate = 0;
  }
  out.frame_rate = rate;

  // Analog values per frame (skipped, but they sit between the frames).
  std::size_t analog_per_frame = header_analog;
  const auto analog_used = count("ANALOG", "USED");
  const auto analog_rate = number("ANALOG", "RATE");
  if (analog_used && analog_rate && std::isfinite(*analog_rate) && *analog_rate >= 0 && *analog_rate <= 1e9) {
    out.analog_channels = *analog_used;
    out.analog_rate = out.analog_channels > 0 ? *analog_rate : 0;
    if (rate > 0 && out.analog_channels > 0 && out.analog_channels <= 65535) {
      const double per = std::min(std::round(*analog_rate / rate), 1e9);
      const std::size_t from_params = out.analog_channels * static_cast<std::size_t>(per);
      if (from_params != header_analog) {
        warn(4, "header says " + std::to_string(header_analog) + " analog values per frame, ANALOG:USED x RATE " +
                    std::to_string(from_params) + ": using the header");
      }
    }
  }

  // Data start: the parameter wins when the two disagree.
  std::size_t data_block = header_data_block;
  if (auto d = count("POINT", "DATA_START")) {
    const std::size_t from_param = *d;
    if (from_param != header_data_block && from_param > 0) {
      warn(16, "header puts the data at block " + std::to_string(header_data_block) + ", POINT:DATA_START at " +
                   std::to_string(from_param) + ": using POINT:DATA_START");
      data_block = from_param;
    }
  }
  if (data_block == 0) return byte_error(label_, 16, "data section at block 0 (blocks count from 1)");
  const std::size_t data_start = (data_block - 1) * kBlock;
  if (data_block <= param_block) {
    return byte_error(label_, 16,
                      "data section (block " + std::to_string(data_block) +
                          ") starts before the end of the parameter section (block " + std::to_string(param_block) +
                          ")");
  }

  // Frames: POINT:FRAMES (int16 read unsigned, or float), TRIAL:ACTUAL_*_FIELD
  // (two 16-bit words, low first) when present; the header's 16-bit words
  // overflow (Vicon writes 65535).
  std::int64_t first = static_cast<std::int64_t>(header_first);
  std::uint64_t frames = header_last >= header_first ? header_last - header_first + 1 : 0;
  // Neither POINT:FRAMES nor TRIAL:* and an overflowed header: count what the file holds.
  bool frames_from_size = header_last == 65535;
  if (auto f = number("POINT", "FRAMES", 0, true)) {
    if (*f >= 0 && *f <= static_cast<double>(kMaxFrames)) {
      frames = static_cast<std::uint64_t>(*f);
      frames_from_size = false;
    }
  }
  {
    const Parameter* s = find("TRIAL", "ACTUAL_START_FIELD");
    const Parameter* e = find("TRIAL", "ACTUAL_END_FIELD");
    if (s && e && s->type == 2 && e->type == 2 && s->count >= 2 && e->count >= 2) {
      const std::int64_t a = dec_.u16(s->data) | std::int64_t{dec_.u16(s->data + 2)} << 16;
      const std::int64_t b = dec_.u16(e->data) | std::int64_t{dec_.u16(e->data + 2)} << 16;
      // Only believed when the header's 16-bit words overflowed.
      if (b >= a && header_last == 65535) {
        frames = static_cast<std::uint64_t>(b - a + 1);
        first = a;
        frames_from_size = false;
      }
    }
  }
  out.first_frame = first;

  // Bound everything by the bytes present before allocating; frames without
  // markers or analog samples carry no bytes and are capped (gmr/core/limits.h).
  const std::size_t frame_bytes = (points * 4 + analog_per_frame) * value_size;
  if (auto s = check_frame_count(frames, frame_bytes); !s.ok()) return byte_error(label_, 8, s.error().message);
  if (frames > 0 && frame_bytes > 0) {
    if (data_start > bytes_.size()) {
      return byte_error(label_, 16,
                        "data section at block " + std::to_string(data_block) + " (byte " + std::to_string(data_start) +
                            ") is past the end of the file (" + std::to_string(bytes_.size()) + " bytes)");
    }
    const std::size_t available = (bytes_.size() - data_start) / frame_bytes;
    if (frames_from_size && available != frames) {
      warn(8, "header's last frame is 65535 (overflow) and no POINT:FRAMES: using the " + std::to_string(available) +
                  " frames the file holds");
      frames = available;
    }
    if (available < frames) {
      // Like a TRC whose NumFrames is too large: keep the whole frames present.
      warn(bytes_.size(), "file ends in frame " + std::to_string(available) + " of " + std::to_string(frames) +
                              " (each " + std::to_string(frame_bytes) + " bytes from byte " +
                              std::to_string(data_start) + "): loaded the " + std::to_string(available) +
                              " whole frames");
      frames = available;
    }
  }

  // Labels: LABELS, LABELS2, LABELS3, ... until every point has one.
  std::vector<std::string> labels = strings("POINT", "LABELS");
  for (int k = 2; labels.size() < points && k < 1000; ++k) {
    if (!find("POINT", "LABELS" + std::to_string(k))) break;
    const auto more = strings("POINT", "LABELS" + std::to_string(k));
    labels.insert(labels.end(), more.begin(), more.end());
  }
  labels.resize(std::min(labels.size(), points));
  if (labels.size() < points) {
    warn(0, std::to_string(points - labels.size()) + " of " + std::to_string(points) +
                " points have no label: named Point<N> (N from 1)");
  }
  out.names.reserve(points);
  for (std::size_t i = 0; i < points; ++i) {
    std::string name = i < labels.size() ? labels[i] : std::string();
    if (name.empty()) name = "Point" + std::to_string(i + 1);
    out.names.push_back(std::move(name));
  }
  // Some files repeat a label: later ones get _2, _3, ...
  if (detail::make_names_unique(out.names)) warn(0, "duplicate point labels: later ones renamed with _2, _3, ...");

  // Units: some writers repeat the unit in one string ("mmmm..."): keep one.
  {
    const auto u = strings("POINT", "UNITS");
    out.units = u.empty() ? std::string() : u[0];
    constexpr std::string_view kKnown[] = {"mm", "cm", "dm", "m", "in", "ft"};
    const bool is_known = std::find(std::begin(kKnown), std::end(kKnown), out.units) != std::end(kKnown);
    for (std::string_view known : kKnown) {
      if (is_known) break;
      const std::string& s = out.units;
      if (s.size() <= known.size() || s.size() % known.size() != 0) continue;
      bool repeated = true;
      for (std::size_t i = 0; i < s.size() && repeated; ++i) repeated = s[i] == known[i % known.size()];
      if (repeated) {
        out.units = std::string(known);
        break;
      }
    }
  }

  if (frame_bytes == 0) {  // no points and no analog: only the frame count
    out.frame_count = static_cast<std::size_t>(frames);
    return out;
  }
  out.frame_count = static_cast<std::size_t>(frames);
  const double nan = std::numeric_limits<double>::quiet_NaN();
  out.positions.assign(out.frame_count * points * 3, nan);
  out.residuals.assign(out.frame_count * points, nan);
  for (std::size_t f = 0; f < out.frame_count; ++f) {
    std::size_t at_byte = data_start + f * frame_bytes;
    for (std::size_t m = 0; m < points; ++m, at_byte += 4 * value_size) {
      double xyz[3];
      int word4;
      if (floats) {
        for (int a = 0; a < 3; ++a) xyz[a] = dec_.f32(at_byte + 4 * static_cast<std::size_t>(a));
        const double w = dec_.f32(at_byte + 12);
        // The residual word is stored as a float holding an int16's value.
        word4 = std::isfinite(w) && std::fabs(w) < 32768.0 ? static_cast<int>(w) : -1;
      } else {
        for (int a = 0; a < 3; ++a) xyz[a] = dec_.i16(at_byte + 2 * static_cast<std::size_t>(a)) * abs_scale;
        word4 = dec_.i16(at_byte + 6);
      }
      if (word4 < 0 || !std::isfinite(xyz[0]) || !std::isfinite(xyz[1]) || !std::isfinite(xyz[2])) continue;
      const std::size_t i = out.index(f, m);
      out.positions[i] = xyz[0];
      out.positions[i + 1] = xyz[1];
      out.positions[i + 2] = xyz[2];
      out.residuals[f * points + m] = static_cast<double>(word4 & 0xff) * abs_scale;
    }
  }
  return out;
}

}  // namespace

Result<MarkerTrajectories> parse_c3d(std::string_view bytes, std::string_view file_label, Warnings* out_warnings) {
  return C3dReader(bytes, file_label, out_warnings).read();
}

Result<MarkerTrajectories> read_c3d(const std::filesystem::path& path, Warnings* out_warnings) {
  auto bytes = read_file(path);
  if (!bytes) return bytes.error();
  return parse_c3d(*bytes, path.string(), out_warnings);
}

}  // namespace gmr
