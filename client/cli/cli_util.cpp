#include "cli_util.h"

#include "gmr/io/motion_file.h"

#include <cctype>
#include <charconv>
#include <cstdio>

namespace gmr::cli {
namespace {

std::size_t parse_index(std::string_view s, std::string_view whole) {
  std::size_t v = 0;
  const auto [p, ec] = std::from_chars(s.data(), s.data() + s.size(), v);
  if (ec != std::errc() || p != s.data() + s.size())
    throw CommandError("bad frame range '" + std::string(whole) + "': expected A:B with non-negative integers");
  return v;
}

}  // namespace

FrameRange parse_frame_range(std::string_view text) {
  const auto colon = text.find(':');
  if (colon == std::string_view::npos)
    throw CommandError("bad frame range '" + std::string(text) + "': expected A:B (frames A to B-1)");
  FrameRange r;
  const auto a = text.substr(0, colon), b = text.substr(colon + 1);
  if (!a.empty()) r.begin = parse_index(a, text);
  if (!b.empty()) r.end = parse_index(b, text);
  if (r.begin > r.end) throw CommandError("bad frame range '" + std::string(text) + "': A is after B");
  return r;
}

FrameRange clamp_frame_range(FrameRange r, std::size_t frame_count) {
  // The rule of the protocol's QueryFrames: begin < end <= frame_count. An
  // open end means the last frame; ':' on a motion with no frames is empty.
  const bool open_end = r.end == static_cast<std::size_t>(-1);
  if (open_end) r.end = frame_count;
  if (open_end && r.begin == 0 && frame_count == 0) return r;
  if (!(r.begin < r.end && r.end <= frame_count)) {
    throw CommandError("frames [" + std::to_string(r.begin) + ", " + (open_end ? "end" : std::to_string(r.end)) +
                       ") are not within the motion's " + std::to_string(frame_count) + " frames");
  }
  return r;
}

std::vector<std::string> split_list(std::string_view text) {
  std::vector<std::string> out;
  std::size_t start = 0;
  while (true) {
    const auto comma = text.find(',', start);
    const auto item = text.substr(start, comma == std::string_view::npos ? std::string_view::npos : comma - start);
    if (item.empty()) throw CommandError("empty name in list '" + std::string(text) + "'");
    out.emplace_back(item);
    if (comma == std::string_view::npos) break;
    start = comma + 1;
  }
  return out;
}

void print_warnings(const Warnings& warnings) {
  for (const Error& w : warnings) std::fprintf(stderr, "gmr: warning: %s\n", w.to_string().c_str());
}

std::string tree_indent(int depth) {
  constexpr int kMaxIndentLevels = 32;
  if (depth <= kMaxIndentLevels) return std::string(2 * static_cast<std::size_t>(depth), ' ');
  return std::string(2 * kMaxIndentLevels, ' ') + "[depth " + std::to_string(depth) + "] ";
}

Motion load(const std::string& file, const std::string& asf, double fps, Warnings& warnings) {
  LoadOptions options;
  options.asf = asf;
  options.amc_fps = fps;
  return take(load_motion(file, options, &warnings));
}

}  // namespace gmr::cli
