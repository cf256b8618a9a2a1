/* Links the installed C ABI (through CMake's gmr::client_c, or pkg-config):
 * connects to the gmr-server whose port is argv[1] and polls a frame. */
#define _POSIX_C_SOURCE 200809L
#include <stdio.h>
#include <stdlib.h>
#include <time.h>

#include "gmr_client_c.h"

int main(int argc, char** argv) {
  if (argc != 2) return 2;
  gmr_client* c = NULL;
  if (gmr_connect("127.0.0.1", (uint16_t)atoi(argv[1]), NULL, &c) != GMR_OK) {
    fprintf(stderr, "connect: %s\n", gmr_last_error());
    return 1;
  }
  gmr_motion_info m[16];
  size_t count = 0;
  uint32_t view = 0;
  if (gmr_list_motions(c, m, 16, &count) != GMR_OK || count == 0 || gmr_create_view(c, m[0].name, &view) != GMR_OK) {
    return 1;
  }
  gmr_subscribe_options o;
  gmr_subscribe_options_init(&o);
  o.max_frames = 5;
  gmr_subscription* s = NULL;
  if (gmr_subscribe(c, view, &o, &s) != GMR_OK) return 1;
  static double positions[3 * 256];
  gmr_frame f;
  gmr_status st = GMR_NO_FRAME;
  for (int i = 0; i < 5000 && st == GMR_NO_FRAME; ++i) {
    st = gmr_poll_frame(s, &f, positions, NULL, NULL, NULL, 256);
    struct timespec ts = {0, 1000000};
    nanosleep(&ts, NULL);
  }
  if (st != GMR_OK || f.joint_count != m[0].joint_count) return 1;
  printf("c consumer: frame %llu of %s, %u joints\n", (unsigned long long)f.frame_index, m[0].name, f.joint_count);
  gmr_unsubscribe(s);
  gmr_disconnect(c);
  return 0;
}
