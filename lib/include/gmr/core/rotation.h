// Channels and Euler angles.
//
// A joint's rotation channels compose in the order they are listed, as
// intrinsic rotations: `Zrotation Xrotation Yrotation` is R = Rz * Rx * Ry.
// Angles in channel values are degrees. Position channels REPLACE the matching
// component of the joint's static offset (they do not add to it).
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstdint>
#include <optional>
#include <span>
#include <string_view>

namespace gmr {

enum class Axis : std::uint8_t { kX = 0, kY = 1, kZ = 2 };

enum class ChannelType : std::uint8_t {
  kXposition = 0,
  kYposition = 1,
  kZposition = 2,
  kXrotation = 3,
  kYrotation = 4,
  kZrotation = 5,
};

constexpr bool is_rotation(ChannelType c) { return static_cast<int>(c) >= 3; }
constexpr bool is_position(ChannelType c) { return static_cast<int>(c) < 3; }
constexpr Axis axis_of(ChannelType c) { return static_cast<Axis>(static_cast<int>(c) % 3); }
constexpr ChannelType rotation_channel(Axis a) { return static_cast<ChannelType>(3 + static_cast<int>(a)); }
constexpr ChannelType position_channel(Axis a) { return static_cast<ChannelType>(static_cast<int>(a)); }

// "Xposition", ..., "Zrotation": the BVH spelling, also used by the GMR format.
std::string_view channel_name(ChannelType c);
// Parses the BVH spelling (case-insensitive); nullopt when unknown.
std::optional<ChannelType> parse_channel(std::string_view name);

// Rotation by `degrees` about one axis.
Eigen::Matrix3d axis_rotation(Axis axis, double degrees);

// Product of the rotation channels among `channels`, in listed order, taking
// their values from `values` (same length as channels). Position channels are
// skipped. Identity when there is no rotation channel.
Eigen::Matrix3d compose_rotation(std::span<const ChannelType> channels, std::span<const double> values);

// Angles (degrees) a, b, c such that R = R_order[0](a) * R_order[1](b) * R_order[2](c),
// for any order of three distinct axes. Reconstruction is accurate to round-off
// even at gimbal lock (the last angle is solved from the residual rotation).
// `hint`, when given, picks among equivalent solutions the one closest to it
// (angles may differ from the hint by multiples of 360 to stay continuous).
Eigen::Vector3d decompose_euler(const Eigen::Matrix3d& R, const Axis order[3], const Eigen::Vector3d* hint = nullptr);

}  // namespace gmr
