/* The C ABI from plain C (C11, no C++ anywhere in this file): connects to
 * the gmr-server whose port is argv[1], streams 30 frames of the demo walk
 * re-rooted at the head in Unity's conventions with local transforms, and
 * checks that composing the locals from the roots down gives the positions;
 * then the error paths. Prints one line per frame ("frame INDEX x y z" of
 * joint 0 and the largest composition error) for the driver to compare with
 * `gmr positions`. Exit 0 when every check passed. */
#define _POSIX_C_SOURCE 200809L
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "gmr_client_c.h"

#define CHECK(cond, ...)                           \
  do {                                             \
    if (!(cond)) {                                 \
      fprintf(stderr, "FAIL line %d: ", __LINE__); \
      fprintf(stderr, __VA_ARGS__);                \
      fprintf(stderr, "\n");                       \
      exit(1);                                     \
    }                                              \
  } while (0)

enum { kMaxJoints = 256 };

/* r = a * b for 3x3 row-major matrices; m from a unit quaternion x y z w. */
static void mul(const double* a, const double* b, double* r) {
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) r[3 * i + j] = a[3 * i] * b[j] + a[3 * i + 1] * b[3 + j] + a[3 * i + 2] * b[6 + j];
}
static void matrix(const double* q, double* m) {
  const double x = q[0], y = q[1], z = q[2], w = q[3];
  const double v[9] = {1 - 2 * (y * y + z * z), 2 * (x * y - z * w),     2 * (x * z + y * w),
                       2 * (x * y + z * w),     1 - 2 * (x * x + z * z), 2 * (y * z - x * w),
                       2 * (x * z - y * w),     2 * (y * z + x * w),     1 - 2 * (x * x + y * y)};
  memcpy(m, v, sizeof v);
}

int main(int argc, char** argv) {
  CHECK(argc == 2, "usage: c_abi_test PORT");
  CHECK(gmr_abi_version() == GMR_CLIENT_C_ABI_VERSION, "ABI version %d", gmr_abi_version());
  gmr_client* c = NULL;
  gmr_status s = gmr_connect("127.0.0.1", (uint16_t)atoi(argv[1]), NULL, &c);
  CHECK(s == GMR_OK, "connect: %d %s", s, gmr_last_error());

  gmr_motion_info motions[8];
  size_t count = 0;
  s = gmr_list_motions(c, motions, 8, &count);
  CHECK(s == GMR_OK && count == 4, "list: %d, %zu motions: %s", s, count, gmr_last_error());
  CHECK(strcmp(motions[0].name, "walk") == 0 || strcmp(motions[3].name, "walk") == 0 ||
            strcmp(motions[1].name, "walk") == 0 || strcmp(motions[2].name, "walk") == 0,
        "no walk");

  uint32_t view = 0;
  s = gmr_create_view(c, "walk", &view);
  CHECK(s == GMR_OK, "create_view: %s", gmr_last_error());
  s = gmr_shift_root(c, view, "head");
  CHECK(s == GMR_OK, "shift_root: %s", gmr_last_error());

  gmr_subscribe_options o;
  gmr_subscribe_options_init(&o);
  o.preset = GMR_PRESET_UNITY;
  o.local_transforms = 1;
  o.float64 = 1;
  o.end_frame = 30;
  o.speed = 4;
  gmr_subscription* sub = NULL;
  s = gmr_subscribe(c, view, &o, &sub);
  CHECK(s == GMR_OK, "subscribe: %s", gmr_last_error());

  size_t joints = 0;
  CHECK(gmr_subscription_joint_count(sub, &joints) == GMR_OK && joints == 22, "%zu joints", joints);
  double unit = -1;
  CHECK(gmr_subscription_metres_per_unit(sub, &unit) == GMR_OK && unit == 1.0, "unit %g m (Unity's: metres)", unit);
  CHECK(gmr_subscription_metres_per_unit(sub, NULL) == GMR_ERROR_INVALID_ARGUMENT, "a NULL unit pointer accepted");
  gmr_joint_info info[kMaxJoints];
  int roots = 0;
  for (size_t j = 0; j < joints; ++j) {
    CHECK(gmr_subscription_joint(sub, j, &info[j]) == GMR_OK, "joint %zu: %s", j, gmr_last_error());
    CHECK(info[j].parent < (int32_t)j, "joint %zu has parent %d", j, info[j].parent);
    if (info[j].parent < 0) {
      ++roots;
      CHECK(strcmp(info[j].name, "head") == 0, "the root is %s", info[j].name);
    }
    CHECK(fabs(info[j].rest_rotation[3] - 1.0) < 1e-12, "rest rotation of %s", info[j].name);
  }
  CHECK(roots == 1, "%d roots", roots);

  static double pos[3 * kMaxJoints], rot[4 * kMaxJoints], trans[3 * kMaxJoints];
  static double own[9 * kMaxJoints], composed[3 * kMaxJoints];
  int frames = 0;
  for (int polls = 0; polls < 20000; ++polls) {
    gmr_frame f;
    s = gmr_poll_frame(sub, &f, pos, NULL, rot, trans, kMaxJoints);
    if (s == GMR_ENDED) break;
    if (s == GMR_NO_FRAME) {
      struct timespec ts = {0, 1000000};
      nanosleep(&ts, NULL);
      continue;
    }
    CHECK(s == GMR_OK, "poll: %d %s", s, gmr_last_error());
    CHECK(f.joint_count == joints && f.has_local_transforms, "frame of %u joints", f.joint_count);
    double worst = 0;
    for (size_t j = 0; j < joints; ++j) {
      double q[9];
      matrix(rot + 4 * j, q);
      const int p = info[j].parent;
      if (p < 0) {
        memcpy(own + 9 * j, q, sizeof q);
        memcpy(composed + 3 * j, trans + 3 * j, 3 * sizeof(double));
      } else {
        mul(own + 9 * p, q, own + 9 * j);
        for (int k = 0; k < 3; ++k) {
          const double* o3 = own + 9 * p + 3 * k;
          composed[3 * j + k] =
              composed[3 * p + k] + o3[0] * trans[3 * j] + o3[1] * trans[3 * j + 1] + o3[2] * trans[3 * j + 2];
        }
      }
      for (int k = 0; k < 3; ++k) worst = fmax(worst, fabs(composed[3 * j + k] - pos[3 * j + k]));
    }
    CHECK(worst < 1e-9, "frame %llu: the locals compose %.3g off the positions", (unsigned long long)f.frame_index,
          worst);
    /* On one host: encoded, then written to this subscriber, then parsed here. */
    int64_t sent_ns = 0, written_ns = 0, received_ns = 0;
    CHECK(gmr_last_frame_times(sub, &sent_ns, &written_ns, &received_ns) == GMR_OK, "times: %s", gmr_last_error());
    CHECK(sent_ns == f.server_send_time_ns && sent_ns > 0 && sent_ns <= written_ns && written_ns <= received_ns,
          "frame %llu: sent %lld, written %lld, received %lld", (unsigned long long)f.frame_index, (long long)sent_ns,
          (long long)written_ns, (long long)received_ns);
    for (size_t j = 0; j < joints; ++j) {
      printf("frame %llu %s %.17g %.17g %.17g\n", (unsigned long long)f.frame_index, info[j].name, pos[3 * j],
             pos[3 * j + 1], pos[3 * j + 2]);
    }
    ++frames;
  }
  CHECK(frames >= 5, "only %d frames polled", frames);
  uint64_t received = 0, replaced = 0;
  CHECK(gmr_subscription_counts(sub, &received, &replaced) == GMR_OK, "counts");
  CHECK(gmr_last_frame_times(NULL, NULL, NULL, NULL) == GMR_ERROR_INVALID_ARGUMENT, "times of NULL");
  CHECK(gmr_last_frame_times(sub, NULL, NULL, NULL) == GMR_OK, "times into NULL pointers");
  CHECK(received == 30 && received == (uint64_t)frames + replaced, "received %llu, replaced %llu, polled %d",
        (unsigned long long)received, (unsigned long long)replaced, frames);
  gmr_unsubscribe(sub);

  /* Errors: a status and a message that says what. */
  uint32_t none = 0;
  s = gmr_create_view(c, "no_such_motion", &none);
  CHECK(s == GMR_ERROR_NOT_FOUND && strstr(gmr_last_error(), "no_such_motion"), "%d %s", s, gmr_last_error());
  s = gmr_shift_root(c, view, "no_such_joint");
  CHECK(s == GMR_ERROR_NOT_FOUND, "%d %s", s, gmr_last_error());
  CHECK(gmr_create_view(NULL, "walk", &none) == GMR_ERROR_INVALID_ARGUMENT, "NULL client");
  CHECK(gmr_poll_frame(NULL, NULL, NULL, NULL, NULL, NULL, 0) == GMR_ERROR_INVALID_ARGUMENT, "NULL subscription");
  gmr_subscribe_options bad;
  memset(&bad, 0, sizeof bad);
  CHECK(gmr_subscribe(c, view, &bad, &sub) == GMR_ERROR_INVALID_ARGUMENT && strstr(gmr_last_error(), "struct_size"),
        "uninitialised options: %s", gmr_last_error());
  gmr_client* nobody = NULL;
  s = gmr_connect("127.0.0.1", 1, NULL, &nobody);
  CHECK(s == GMR_ERROR_CONNECTION && nobody == NULL, "connect to port 1: %d", s);
  /* Split, join back, strip dummies; a query in Unity's conventions equals
   * the frames polled above (positions do not change with the roots). */
  CHECK(gmr_split(c, view, "l_knee") == GMR_OK, "split: %s", gmr_last_error());
  CHECK(gmr_join(c, view, "l_knee") == GMR_OK, "join: %s", gmr_last_error());
  s = gmr_join(c, view, "head");
  CHECK(s == GMR_ERROR_FAILED_PRECONDITION, "join a root without a soft link: %d %s", s, gmr_last_error());
  CHECK(gmr_strip_dummies(c, view) == GMR_OK, "strip_dummies: %s", gmr_last_error());
  static double queried[3 * kMaxJoints * 2];
  size_t per_frame = 0;
  s = gmr_query_positions(c, view, 0, 2, GMR_PRESET_UNITY, queried, 3 * kMaxJoints * 2, &per_frame);
  CHECK(s == GMR_OK && per_frame == joints, "query: %d %s (%zu joints)", s, gmr_last_error(), per_frame);
  s = gmr_query_positions(c, view, 0, 2, GMR_PRESET_UNITY, queried, 3, &per_frame);
  CHECK(s == GMR_ERROR_INVALID_ARGUMENT && strstr(gmr_last_error(), "values for an array of 3"), "small array: %s",
        gmr_last_error());
  for (size_t j = 0; j < joints; ++j) {
    printf("query %d %s %.17g %.17g %.17g\n", 1, info[j].name, queried[3 * (joints + j)], queried[3 * (joints + j) + 1],
           queried[3 * (joints + j) + 2]);
  }
  CHECK(gmr_close_view(c, view) == GMR_OK, "close_view: %s", gmr_last_error());

  /* Retargeting: the demo walk on a 15-joint rig with Unity's humanoid names
   * (a T-pose in centimetres), then polled on the rig's joints. */
  {
    static const gmr_channel rot[3] = {GMR_CHANNEL_Z_ROTATION, GMR_CHANNEL_X_ROTATION, GMR_CHANNEL_Y_ROTATION};
    const struct {
      const char* name;
      int32_t parent;
      double x, y, z;
    } bones[15] = {{"Hips", -1, 0, 100, 0},          {"Spine", 0, 0, 10, 0},           {"Head", 1, 0, 50, 0},
                   {"LeftUpperArm", 1, 20, 40, 0},   {"LeftLowerArm", 3, 30, 0, 0},    {"LeftHand", 4, 25, 0, 0},
                   {"RightUpperArm", 1, -20, 40, 0}, {"RightLowerArm", 6, -30, 0, 0},  {"RightHand", 7, -25, 0, 0},
                   {"LeftUpperLeg", 0, 10, -5, 0},   {"LeftLowerLeg", 9, 0, -45, 0},   {"LeftFoot", 10, 0, -45, 0},
                   {"RightUpperLeg", 0, -10, -5, 0}, {"RightLowerLeg", 12, 0, -45, 0}, {"RightFoot", 13, 0, -45, 0}};
    gmr_publish_joint rig[15];
    for (int i = 0; i < 15; ++i) {
      memset(&rig[i], 0, sizeof rig[i]);
      rig[i].name = bones[i].name;
      rig[i].parent = bones[i].parent;
      rig[i].offset[0] = bones[i].x;
      rig[i].offset[1] = bones[i].y;
      rig[i].offset[2] = bones[i].z;
      rig[i].channel_count = i == 0 ? 6 : 3;
      for (int k = 0; k < 3; ++k) {
        if (i == 0) rig[i].channels[k] = (gmr_channel)(GMR_CHANNEL_X_POSITION + k);
        rig[i].channels[i == 0 ? 3 + k : k] = rot[k];
      }
    }
    uint32_t rv = 0;
    CHECK(gmr_create_view(c, "walk", &rv) == GMR_OK, "create_view: %s", gmr_last_error());
    s = gmr_retarget(c, rv, rig, 1, NULL, 0);
    CHECK(s == GMR_ERROR_FAILED_PRECONDITION && strstr(gmr_last_error(), "required roles without a joint: head"),
          "one joint: %d %s", s, gmr_last_error());
    CHECK(gmr_retarget(c, rv, NULL, 2, NULL, 0) == GMR_ERROR_INVALID_ARGUMENT, "NULL joints");
    CHECK(gmr_retarget(c, rv, rig, 15, NULL, 0) == GMR_OK, "retarget: %s", gmr_last_error());
    gmr_subscribe_options ro;
    gmr_subscribe_options_init(&ro);
    ro.float64 = 1;
    ro.end_frame = 5;
    ro.speed = 4;
    gmr_subscription* rs = NULL;
    CHECK(gmr_subscribe(c, rv, &ro, &rs) == GMR_OK, "subscribe: %s", gmr_last_error());
    size_t rig_joints = 0;
    CHECK(gmr_subscription_joint_count(rs, &rig_joints) == GMR_OK && rig_joints == 15, "%zu rig joints", rig_joints);
    gmr_joint_info first;
    CHECK(gmr_subscription_joint(rs, 0, &first) == GMR_OK && strcmp(first.name, "Hips") == 0, "joint 0 is %s",
          first.name);
    gmr_frame rf;
    static double rp[3 * 15];
    int got = 0;
    for (int tries = 0; tries < 2000 && got == 0; ++tries) {
      s = gmr_poll_frame(rs, &rf, rp, NULL, NULL, NULL, 15);
      if (s == GMR_OK) {
        got = 1;
      } else {
        struct timespec ts = {0, 5 * 1000 * 1000};
        nanosleep(&ts, NULL);
      }
    }
    CHECK(got && rf.joint_count == 15, "no frame on the rig (%d)", s);
    /* The rig's head is above its hips, by the rig's spine and neck (60 cm less what the walk bends). */
    CHECK(rp[3 * 2 + 1] - rp[1] > 40 && rp[3 * 2 + 1] - rp[1] <= 60.000001, "head %.3f above hips",
          rp[3 * 2 + 1] - rp[1]);
    gmr_unsubscribe(rs);
    CHECK(gmr_close_view(c, rv) == GMR_OK, "close_view: %s", gmr_last_error());

    /* The same rig with a map of its own, said to be in inches (the walk is in
     * centimetres): bad maps refused with the joint or role named, then the
     * view in the rig's unit. */
    static const gmr_role_joint map[15] = {{"hips", "Hips"},
                                           {"spine", "Spine"},
                                           {"head", "Head"},
                                           {"left_upper_arm", "LeftUpperArm"},
                                           {"left_lower_arm", "LeftLowerArm"},
                                           {"left_hand", "LeftHand"},
                                           {"right_upper_arm", "RightUpperArm"},
                                           {"right_lower_arm", "RightLowerArm"},
                                           {"right_hand", "RightHand"},
                                           {"left_upper_leg", "LeftUpperLeg"},
                                           {"left_lower_leg", "LeftLowerLeg"},
                                           {"left_foot", "LeftFoot"},
                                           {"right_upper_leg", "RightUpperLeg"},
                                           {"right_lower_leg", "RightLowerLeg"},
                                           {"right_foot", "RightFoot"}};
    CHECK(gmr_create_view(c, "walk", &rv) == GMR_OK, "create_view: %s", gmr_last_error());
    gmr_role_joint wrong[15];
    memcpy(wrong, map, sizeof wrong);
    wrong[5].joint = "LeftPaw";
    s = gmr_retarget_mapped(c, rv, rig, 15, NULL, 0, wrong, 15, NULL, 0, 0.01);
    CHECK(s == GMR_ERROR_FAILED_PRECONDITION && strstr(gmr_last_error(), "'LeftPaw'"), "absent joint: %d %s", s,
          gmr_last_error());
    wrong[5] = map[4];
    s = gmr_retarget_mapped(c, rv, rig, 15, NULL, 0, wrong, 15, NULL, 0, 0.01);
    CHECK(s == GMR_ERROR_INVALID_ARGUMENT && strstr(gmr_last_error(), "'left_lower_arm' is given twice"),
          "a role twice: %d %s", s, gmr_last_error());
    wrong[5].role = NULL;
    CHECK(gmr_retarget_mapped(c, rv, rig, 15, NULL, 0, wrong, 15, NULL, 0, 0.01) == GMR_ERROR_INVALID_ARGUMENT,
          "a NULL role");
    CHECK(gmr_retarget_mapped(c, rv, rig, 15, NULL, 0, map, 15, NULL, 0, -1.0) == GMR_ERROR_BAD_REQUEST,
          "a negative unit");
    CHECK(gmr_retarget_mapped(c, rv, rig, 15, NULL, 0, map, 15, NULL, 0, 0.0254) == GMR_OK, "mapped: %s",
          gmr_last_error());
    CHECK(gmr_subscribe(c, rv, &ro, &rs) == GMR_OK, "subscribe: %s", gmr_last_error());
    double unit = 0;
    CHECK(gmr_subscription_metres_per_unit(rs, &unit) == GMR_OK && unit == 0.0254, "the rig's unit: %g", unit);
    gmr_unsubscribe(rs);
    CHECK(gmr_close_view(c, rv) == GMR_OK, "close_view: %s", gmr_last_error());
  }
  gmr_disconnect(c);
  fprintf(stderr, "c abi: %d frames polled of %llu received, locals compose to the positions\n", frames,
          (unsigned long long)received);
  return 0;
}
