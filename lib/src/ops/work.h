// Private editable form of a motion used by the conversions and operations.
//
// Each joint is a Track that holds its rotation channels and its position
// channels separately (with their values for every frame), so an operation can
// replace one without touching the other, copy channels exactly where the
// formula is a plain copy, and re-encode computed rotations as Euler channels.
// Tracks may be marked removed; to_motion() drops them and puts parents before
// children again (stable: among joints that are ready, the lowest index first).
#pragma once

#include <Eigen/Core>
#include <span>
#include <string>
#include <vector>

#include "gmr/core/error.h"
#include "gmr/motion/motion.h"

namespace gmr::detail {

struct Track {
  std::string name;
  int parent = kNoParent;
  int soft_parent = kNoParent;
  bool removed = false;
  Eigen::Vector3d offset = Eigen::Vector3d::Zero();
  std::vector<ChannelType> pos_ch;  // position channels: replace offset components
  std::vector<double> pos_v;        // frames x pos_ch.size()
  std::vector<ChannelType> rot_ch;  // rotation channels, composed in listed order
  std::vector<double> rot_v;        // frames x rot_ch.size()

  bool has_rotation() const { return !rot_ch.empty(); }
  Eigen::Matrix3d rotation(std::size_t f) const;
  Eigen::Vector3d translation(std::size_t f) const;
};

struct Work {
  std::vector<Track> tracks;
  std::size_t frames = 0;
  double frame_time = 0.0;
  Convention convention = Convention::kPreRotation;

  static Work from_motion(const Motion& m);
  // Drops removed tracks (remapping parents and soft links to the nearest kept
  // ancestor), reorders parents first, and validates.
  Result<Motion> to_motion() const;

  int size() const { return static_cast<int>(tracks.size()); }
  Track& operator[](int j) { return tracks[static_cast<std::size_t>(j)]; }
  const Track& operator[](int j) const { return tracks[static_cast<std::size_t>(j)]; }
  // Children of j (not removed), in index order.
  std::vector<int> children(int j) const;
};

// Per-frame rotation matrices of a track.
std::vector<Eigen::Matrix3d> rotations(const Track& t, std::size_t frames);

// Stores per-frame rotations as Euler channels of `t` (its position channels
// are kept). Order: t's own axes when it has three; otherwise its axes followed
// by the missing ones in X, Y, Z order, dropping trailing added axes whose angle
// is 0 (mod 360) in every frame; when t has none, `fallback` (if it names three
// axes) or ZXY. All-identity rotations give no rotation channels.
void encode_rotations(Track& t, std::span<const Eigen::Matrix3d> r, std::size_t frames,
                      std::span<const ChannelType> fallback = {});

// Copies the rotation channels (types and values) of `from` into `to`.
void copy_rotation(Track& to, const Track& from);

// Replaces the rotation of `out` by A * B per frame, where A = a's rotation
// (inverted when inv_a) and B = b's. Plain copies stay exact copies: when one
// factor has no rotation channels and the other is not inverted, its channels
// are copied. `out` may be `a` or `b`.
void set_product(Track& out, const Track& a, bool inv_a, const Track& b, std::size_t frames);

// Stores per-frame translations: a static offset when every frame is equal and
// !force_channels, else Xposition Yposition Zposition channels. With no frames,
// `static_value` becomes the offset.
void set_translations(Track& t, std::span<const Eigen::Vector3d> v, std::size_t frames, bool force_channels,
                      const Eigen::Vector3d& static_value);

}  // namespace gmr::detail
