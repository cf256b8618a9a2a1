#include "gmr/demo/demo_library.h"

#include <cmath>
#include <functional>
#include <numbers>

namespace gmr {
namespace {

constexpr double kFrameTime = 1.0 / 60.0;
constexpr double kTwoPi = 2.0 * std::numbers::pi;

struct JointSpec {
  const char* name;
  const char* parent;
  double x, y, z;
};

// Offsets in cm from the parent. Legs hang down, arms stretch out in a T-pose.
constexpr JointSpec kJoints[] = {
    {"pelvis", nullptr, 0, 95, 0},       {"l_hip", "pelvis", 9, -5, 0},        {"l_knee", "l_hip", 0, -42, 0},
    {"l_ankle", "l_knee", 0, -40, 0},    {"l_toe", "l_ankle", 0, -6, 14},      {"r_hip", "pelvis", -9, -5, 0},
    {"r_knee", "r_hip", 0, -42, 0},      {"r_ankle", "r_knee", 0, -40, 0},     {"r_toe", "r_ankle", 0, -6, 14},
    {"spine", "pelvis", 0, 12, 0},       {"chest", "spine", 0, 24, 0},         {"neck", "chest", 0, 20, 0},
    {"head", "neck", 0, 9, 0},           {"head_top", "head", 0, 18, 0},       {"l_shoulder", "chest", 16, 16, 0},
    {"l_elbow", "l_shoulder", 28, 0, 0}, {"l_wrist", "l_elbow", 25, 0, 0},     {"l_hand", "l_wrist", 9, 0, 0},
    {"r_shoulder", "chest", -16, 16, 0}, {"r_elbow", "r_shoulder", -28, 0, 0}, {"r_wrist", "r_elbow", -25, 0, 0},
    {"r_hand", "r_wrist", -9, 0, 0},
};
constexpr int kJointCount = static_cast<int>(std::size(kJoints));

// Channel values of one frame: for the root, position then Z X Y rotation;
// for every other joint, Z X Y rotation (degrees) of the bone ending at it.
struct Pose {
  double root[6] = {0, 95, 0, 0, 0, 0};
  double rot[kJointCount][3] = {};  // [joint][z, x, y]
  void set(const Skeleton& s, const char* joint, double z, double x, double y) {
    const int j = s.find(joint);
    rot[j][0] = z;
    rot[j][1] = x;
    rot[j][2] = y;
  }
};

Motion generate(const Skeleton& skeleton, int frames, const std::function<void(double, Pose&)>& pose_at) {
  Motion m;
  m.skeleton = skeleton;
  m.convention = Convention::kPreRotation;
  m.frame_time = kFrameTime;
  m.frame_count = static_cast<std::size_t>(frames);
  m.values.reserve(m.frame_count * m.stride());
  for (int f = 0; f < frames; ++f) {
    Pose p;
    // Arms relaxed by default: down at the sides, 75 degrees from the T-pose.
    p.set(skeleton, "l_elbow", -75, 0, 0);
    p.set(skeleton, "r_elbow", 75, 0, 0);
    pose_at(f * kFrameTime, p);
    for (int j = 0; j < kJointCount; ++j) {
      if (j == 0) {
        m.values.insert(m.values.end(), std::begin(p.root), std::end(p.root));
      } else {
        m.values.insert(m.values.end(), std::begin(p.rot[j]), std::end(p.rot[j]));
      }
    }
  }
  return m;
}

// A walk along +Z at 1.2 m/s, one stride per second.
void walk(double t, Pose& p, const Skeleton& s) {
  const double ph = kTwoPi * t;
  p.root[2] = 120.0 * t;
  p.root[1] = 95.0 + 2.0 * std::cos(2 * ph);
  p.root[4] = 3.0 * std::sin(2 * ph);  // pelvis pitch
  p.root[3] = 4.0 * std::sin(ph);      // pelvis roll
  const double l = std::sin(ph), r = std::sin(ph + std::numbers::pi);
  // Thigh swing (bone hip->knee), knee bend (knee->ankle): rotations are
  // relative to the parent bone, so the knee only adds its own bend.
  p.set(s, "l_knee", 0, -28 * l, 0);
  p.set(s, "r_knee", 0, -28 * r, 0);
  p.set(s, "l_ankle", 0, 35 * std::max(0.0, std::sin(ph + 1.2)), 0);
  p.set(s, "r_ankle", 0, 35 * std::max(0.0, std::sin(ph + 1.2 + std::numbers::pi)), 0);
  // Arms hang down (Z) and swing against the legs (Y); forearms bend forward.
  p.set(s, "l_elbow", -75, 0, 20 * l);
  p.set(s, "r_elbow", 75, 0, 20 * l);
  p.set(s, "l_wrist", 0, 0, -15);
  p.set(s, "r_wrist", 0, 0, 15);
  p.set(s, "chest", 0, 0, -6 * l);  // shoulders counter-rotate
}

// Standing, right arm raised, forearm waving.
void wave(double t, Pose& p, const Skeleton& s) {
  const double w = std::sin(kTwoPi * 1.5 * t);
  p.root[1] = 95.0 + 0.5 * std::sin(kTwoPi * 0.5 * t);
  p.set(s, "r_elbow", -20, 0, 0);           // upper arm lifted above the shoulder
  p.set(s, "r_wrist", -70 + 25 * w, 0, 0);  // forearm up, waving side to side
  p.set(s, "r_hand", 20 * w, 0, 0);
  p.set(s, "head", 8 * w, -5, 10);  // the head follows a little
}

// Crouch, jump straight up, land: a 2-second cycle.
void jump(double t, Pose& p, const Skeleton& s) {
  const double c = std::fmod(t, 2.0);
  double crouch = 0.0, height = 0.0;
  if (c < 0.6) {
    crouch = std::sin(std::numbers::pi * c / 0.6);  // down and up again
  } else if (c < 1.2) {
    const double u = (c - 0.6) / 0.6;  // flight: parabola
    height = 40.0 * 4.0 * u * (1.0 - u);
  } else {
    crouch = 0.6 * std::sin(std::numbers::pi * (c - 1.2) / 0.8);
  }
  p.root[1] = 95.0 - 25.0 * crouch + height;
  p.root[4] = 20.0 * crouch;
  for (const char* knee : {"l_knee", "r_knee"}) p.set(s, knee, 0, -60 * crouch, 0);
  for (const char* ankle : {"l_ankle", "r_ankle"}) p.set(s, ankle, 0, 100 * crouch, 0);
  for (const char* toe : {"l_toe", "r_toe"}) p.set(s, toe, 0, -40 * crouch, 0);
  const double arms = height > 0.0 ? 150.0 : -40.0 * crouch;
  p.set(s, "l_elbow", -75 + arms * 0.5, 0, 0);
  p.set(s, "r_elbow", 75 - arms * 0.5, 0, 0);
}

// A slow turn on the spot with the head looking around: exercises the root rotation.
void turn(double t, Pose& p, const Skeleton& s) {
  p.root[5] = 90.0 * t;  // Y rotation
  p.set(s, "neck", 0, 10 * std::sin(kTwoPi * 0.5 * t), 0);
  p.set(s, "head", 0, 0, 45 * std::sin(kTwoPi * 0.25 * t));
  p.set(s, "l_elbow", -75 + 60 * std::sin(kTwoPi * 0.5 * t), 0, 0);
}

}  // namespace

Skeleton demo_skeleton() {
  std::vector<Joint> joints;
  const ChannelType rot[] = {ChannelType::kZrotation, ChannelType::kXrotation, ChannelType::kYrotation};
  for (const JointSpec& spec : kJoints) {
    Joint j;
    j.name = spec.name;
    j.offset = Eigen::Vector3d(spec.x, spec.y, spec.z);
    if (spec.parent == nullptr) {
      j.channels = {ChannelType::kXposition, ChannelType::kYposition, ChannelType::kZposition};
    } else {
      for (std::size_t k = 0; k < joints.size(); ++k) {
        if (joints[k].name == spec.parent) j.parent = static_cast<int>(k);
      }
    }
    j.channels.insert(j.channels.end(), std::begin(rot), std::end(rot));
    joints.push_back(std::move(j));
  }
  return Skeleton::create(std::move(joints)).value();
}

std::vector<NamedMotion> demo_library() {
  const Skeleton s = demo_skeleton();
  using Gen = void (*)(double, Pose&, const Skeleton&);
  const std::pair<const char*, Gen> motions[] = {{"walk", walk}, {"wave", wave}, {"jump", jump}, {"turn", turn}};
  std::vector<NamedMotion> out;
  for (const auto& m : motions) {
    const Gen gen = m.second;  // a plain variable: lambdas may not capture structured bindings (clang 14)
    out.push_back({m.first, generate(s, 240, [&](double t, Pose& p) { gen(t, p, s); })});
  }
  return out;
}

}  // namespace gmr
