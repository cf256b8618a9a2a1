#include "gmr/core/rotation.h"

#include <cctype>
#include <cmath>
#include <numbers>

namespace gmr {
namespace {

constexpr double kDegToRad = std::numbers::pi / 180.0;
constexpr double kRadToDeg = 180.0 / std::numbers::pi;

constexpr std::string_view kNames[] = {"Xposition", "Yposition", "Zposition", "Xrotation", "Yrotation", "Zrotation"};

bool iequals(std::string_view a, std::string_view b) {
  if (a.size() != b.size()) return false;
  for (std::size_t i = 0; i < a.size(); ++i) {
    if (std::tolower(static_cast<unsigned char>(a[i])) != std::tolower(static_cast<unsigned char>(b[i]))) return false;
  }
  return true;
}

// Wraps `angle` by multiples of 360 to the value nearest `target`.
double nearest_turn(double angle, double target) { return angle + 360.0 * std::round((target - angle) / 360.0); }

}  // namespace

std::string_view channel_name(ChannelType c) { return kNames[static_cast<int>(c)]; }

std::optional<ChannelType> parse_channel(std::string_view name) {
  for (int i = 0; i < 6; ++i) {
    if (iequals(name, kNames[i])) return static_cast<ChannelType>(i);
  }
  return std::nullopt;
}

Eigen::Matrix3d axis_rotation(Axis axis, double degrees) {
  const double r = degrees * kDegToRad;
  const double c = std::cos(r), s = std::sin(r);
  Eigen::Matrix3d m;
  switch (axis) {
    case Axis::kX:
      m << 1, 0, 0, 0, c, -s, 0, s, c;
      break;
    case Axis::kY:
      m << c, 0, s, 0, 1, 0, -s, 0, c;
      break;
    case Axis::kZ:
      m << c, -s, 0, s, c, 0, 0, 0, 1;
      break;
  }
  return m;
}

// r * axis_rotation(axis, a) changes only the two columns other than the
// axis: with (p, q) = (y, z), (z, x) or (x, y) for an X, Y or Z rotation,
// column p becomes c p + s q and column q becomes c q - s p. Twelve products
// instead of a full 3x3 multiply, on the path of every frame of every view.
Eigen::Matrix3d compose_rotation(std::span<const ChannelType> channels, std::span<const double> values) {
  Eigen::Matrix3d r = Eigen::Matrix3d::Identity();
  for (std::size_t i = 0; i < channels.size(); ++i) {
    if (!is_rotation(channels[i])) continue;
    const int axis = static_cast<int>(axis_of(channels[i]));
    const int p = (axis + 1) % 3, q = (axis + 2) % 3;
    const double a = values[i] * kDegToRad;
    const double c = std::cos(a), s = std::sin(a);
    const Eigen::Vector3d cp = r.col(p), cq = r.col(q);
    r.col(p) = c * cp + s * cq;
    r.col(q) = c * cq - s * cp;
  }
  return r;
}

// For R = Ri(a) Rj(b) Rk(c) with (i, j, k) distinct axes:
// Let sign = +1 when (i, j, k) is a cyclic permutation of (x, y, z), else -1.
// Then R(i, k) = sign * sin(b), and
//   a = atan2(-sign * R(j, k), R(k, k)),  c = atan2(-sign * R(i, j), R(i, i)).
// We take b from the well-conditioned pair (sin from R(i,k), cos from the norm of
// the row/column), c from the top row, then a from the residual R * Rk(-c) * Rj(-b),
// so that the product reconstructs R to round-off even near gimbal lock.
Eigen::Vector3d decompose_euler(const Eigen::Matrix3d& R, const Axis order[3], const Eigen::Vector3d* hint) {
  const int i = static_cast<int>(order[0]);
  const int j = static_cast<int>(order[1]);
  const int k = static_cast<int>(order[2]);
  assert(i != j && j != k && i != k);
  const double sign = ((j - i + 3) % 3 == 1) ? 1.0 : -1.0;

  const double sb = sign * R(i, k);
  const double cb = std::hypot(R(i, i), R(i, j));
  double b = std::atan2(sb, cb);
  double c = std::atan2(-sign * R(i, j), R(i, i));
  if (cb < 1e-12) c = 0.0;  // gimbal lock: a and c are coupled; put all of it in a

  // Residual rotation about axis i: Ri(a) = R * Rk(-c) * Rj(-b).
  auto solve_a = [&](double bb, double cc) {
    const Eigen::Matrix3d res = R * axis_rotation(order[2], -cc * kRadToDeg) * axis_rotation(order[1], -bb * kRadToDeg);
    // For a rotation about axis i: entry (j, j) = cos a, entry (k, j) = sign * sin a.
    return std::atan2(sign * res(k, j), res(j, j));
  };
  double a = solve_a(b, c);

  Eigen::Vector3d out(a * kRadToDeg, b * kRadToDeg, c * kRadToDeg);
  if (hint != nullptr) {
    // The other solution: (a + 180, 180 - b, c + 180). Pick the one nearest the hint.
    Eigen::Vector3d alt(out[0] + 180.0, 180.0 - out[1], out[2] + 180.0);
    for (int n = 0; n < 3; ++n) {
      out[n] = nearest_turn(out[n], (*hint)[n]);
      alt[n] = nearest_turn(alt[n], (*hint)[n]);
    }
    if ((alt - *hint).squaredNorm() < (out - *hint).squaredNorm()) out = alt;
  }
  return out;
}

}  // namespace gmr
