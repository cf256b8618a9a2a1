/* gmr_client_c: the C ABI of the gmr client, for engine plugins (Unity
 * through C# P/Invoke, Unreal, Godot GDExtension) and any language with a C
 * FFI (Python ctypes). libgmr_client_c.so, SONAME libgmr_client_c.so.0.
 *
 * Handles are opaque. Every function returns a gmr_status; on failure
 * gmr_last_error() gives a one-line message (per thread, valid until this
 * thread's next call). No function throws, aborts or keeps a pointer the
 * caller passed in. Strings are UTF-8 and NUL-terminated.
 *
 * Frames are polled: a subscription keeps the newest frame that arrived (the
 * client's I/O thread receives them), and gmr_poll_frame copies it into the
 * caller's arrays, never waiting. A game loop calls it once per tick.
 *
 *   gmr_client* c; gmr_subscription* s; uint32_t view;
 *   gmr_connect("127.0.0.1", 7400, NULL, &c);
 *   gmr_create_view(c, "walk", &view);
 *   gmr_subscribe_options o; gmr_subscribe_options_init(&o);
 *   o.preset = GMR_PRESET_UNITY; o.local_transforms = 1; o.loop = 1;
 *   gmr_subscribe(c, view, &o, &s);
 *   ... each tick: gmr_poll_frame(s, &frame, positions, rotations, translations, capacity);
 *   gmr_unsubscribe(s); gmr_disconnect(c);
 */
#ifndef GMR_CLIENT_C_H
#define GMR_CLIENT_C_H

#include <stddef.h>
#include <stdint.h>

#if defined(_WIN32)
#define GMR_C_API __declspec(dllimport)
#elif defined(GMR_CLIENT_C_BUILD)
#define GMR_C_API __attribute__((visibility("default")))
#else
#define GMR_C_API
#endif

#ifdef __cplusplus
extern "C" {
#endif

#define GMR_CLIENT_C_ABI_VERSION 1

typedef enum gmr_status {
  GMR_OK = 0,
  GMR_NO_FRAME = 1,                   /* gmr_poll_frame: nothing new since the last poll */
  GMR_ENDED = 2,                      /* the subscription ended (gmr_last_error says why) */
  GMR_ERROR_INVALID_ARGUMENT = 10,    /* a NULL handle or pointer, a buffer too small, ... */
  GMR_ERROR_CONNECTION = 11,          /* cannot connect, or the connection broke */
  GMR_ERROR_BAD_REQUEST = 12,         /* the server refused a field */
  GMR_ERROR_NOT_FOUND = 13,           /* unknown motion, view, joint */
  GMR_ERROR_FAILED_PRECONDITION = 14, /* an impossible operation */
  GMR_ERROR_RESOURCE_EXHAUSTED = 15,  /* a server limit */
  GMR_ERROR_PERMISSION_DENIED = 16,   /* this connection's role may not do that */
  GMR_ERROR_INTERNAL = 17
} gmr_status;

typedef enum gmr_preset {
  GMR_PRESET_NATIVE = 0,
  GMR_PRESET_UNREAL = 1,  /* Z up, X forward, left-handed, cm */
  GMR_PRESET_UNITY = 2,   /* Y up, Z forward, left-handed, m */
  GMR_PRESET_BLENDER = 3, /* Z up, -Y forward, right-handed, m */
  GMR_PRESET_GODOT = 4    /* Y up, -Z forward, right-handed, m */
} gmr_preset;

typedef struct gmr_client gmr_client;
typedef struct gmr_subscription gmr_subscription;

typedef struct gmr_motion_info {
  char name[256]; /* truncated (still NUL-terminated) past 255 bytes */
  uint32_t joint_count;
  uint64_t frame_count;
  double frame_time;      /* seconds */
  double metres_per_unit; /* 0: unknown */
} gmr_motion_info;

typedef struct gmr_joint_info {
  char name[128];
  int32_t parent;             /* -1 for a root */
  double rest_translation[3]; /* relative to the parent's frame, in the subscription's conventions */
  double rest_rotation[4];    /* x, y, z, w */
} gmr_joint_info;

typedef struct gmr_subscribe_options {
  uint32_t struct_size; /* sizeof(gmr_subscribe_options), set by gmr_subscribe_options_init */
  double rate_hz;       /* 0: the motion's own rate times speed */
  double speed;         /* 1: real time */
  int32_t loop;
  int32_t udp;
  int32_t float64;
  int32_t local_transforms; /* each joint's rotation and translation relative to its parent */
  int32_t orientations;     /* world orientations too */
  uint64_t max_frames;      /* 0: no limit */
  uint32_t start_frame, end_frame;
  gmr_preset preset;
  double source_metres_per_unit; /* 0: the library's */
  uint32_t max_staleness_ms;     /* 0: 100 ms */
} gmr_subscribe_options;

typedef struct gmr_frame {
  uint64_t frame_index;
  double motion_time;
  uint64_t sequence;
  int64_t server_send_time_ns;
  uint32_t skeleton_version;
  uint32_t joint_count;     /* values written per array */
  int32_t skeleton_changed; /* 1: the skeleton changed since the last poll (read it again) */
  int32_t has_local_transforms;
  int32_t has_orientations;
} gmr_frame;

GMR_C_API const char* gmr_last_error(void);
GMR_C_API int gmr_abi_version(void);

GMR_C_API gmr_status gmr_connect(const char* host, uint16_t port, const char* token, gmr_client** out);
GMR_C_API void gmr_disconnect(gmr_client* client);

/* Up to `capacity` motions into `out`; *count gets how many the server has. */
GMR_C_API gmr_status gmr_list_motions(gmr_client* client, gmr_motion_info* out, size_t capacity, size_t* count);

GMR_C_API gmr_status gmr_create_view(gmr_client* client, const char* motion, uint32_t* view_id);
GMR_C_API gmr_status gmr_close_view(gmr_client* client, uint32_t view_id);
GMR_C_API gmr_status gmr_shift_root(gmr_client* client, uint32_t view_id, const char* joint);
GMR_C_API gmr_status gmr_set_roots(gmr_client* client, uint32_t view_id, const char* const* roots, size_t count);
GMR_C_API gmr_status gmr_split(gmr_client* client, uint32_t view_id, const char* joint);
GMR_C_API gmr_status gmr_join(gmr_client* client, uint32_t view_id, const char* root);
GMR_C_API gmr_status gmr_strip_dummies(gmr_client* client, uint32_t view_id);
/* The motion seen from `joint`; NULL or "": world coordinates. */
GMR_C_API gmr_status gmr_set_viewpoint(gmr_client* client, uint32_t view_id, const char* joint);

/* Positions of frames [begin, end) of a view in `preset`'s conventions:
 * frame-major, 3 doubles per joint in the view's joint order. `capacity` is
 * how many doubles `positions` holds; *joint_count gets the joints per frame. */
GMR_C_API gmr_status gmr_query_positions(gmr_client* client, uint32_t view_id, uint32_t begin, uint32_t end,
                                         gmr_preset preset, double* positions, size_t capacity, size_t* joint_count);

GMR_C_API void gmr_subscribe_options_init(gmr_subscribe_options* options);
GMR_C_API gmr_status gmr_subscribe(gmr_client* client, uint32_t view_id, const gmr_subscribe_options* options,
                                   gmr_subscription** out);
/* Stops the subscription and frees it. */
GMR_C_API void gmr_unsubscribe(gmr_subscription* subscription);

/* The skeleton of the frames (it changes when the view's structure does:
 * gmr_frame.skeleton_changed). */
GMR_C_API gmr_status gmr_subscription_joint_count(gmr_subscription* subscription, size_t* count);
GMR_C_API gmr_status gmr_subscription_joint(gmr_subscription* subscription, size_t index, gmr_joint_info* out);

/* The unit, in metres, of the subscription's positions and translations
 * (rest pose and local): the preset's when the motion's unit is known, the
 * motion's own with GMR_PRESET_NATIVE, 0 when it is unknown (the numbers are
 * in the motion's units whatever the preset: give source_metres_per_unit, or
 * declare the unit beside the file; docs/protocol.md, "Units"). */
GMR_C_API gmr_status gmr_subscription_metres_per_unit(gmr_subscription* subscription, double* metres_per_unit);

/* The newest frame since the last poll, dropping older ones. Each non-NULL
 * array gets joint_count entries: positions 3 doubles per joint,
 * orientations and local_rotations 4 (x, y, z, w), local_translations 3;
 * `capacity` is the joint count the arrays hold. GMR_NO_FRAME when nothing
 * arrived, GMR_ENDED once the server ended it. */
GMR_C_API gmr_status gmr_poll_frame(gmr_subscription* subscription, gmr_frame* frame, double* positions,
                                    double* orientations, double* local_rotations, double* local_translations,
                                    size_t capacity);

/* When the frame the last gmr_poll_frame returned was encoded by the server
 * (gmr_frame.server_send_time_ns), written by the server to this
 * subscriber's socket, and parsed by this client: nanoseconds of the system
 * clock, the first two the server's and the last this host's (compare them
 * on one host, or with synchronised clocks). write - send is the time the
 * frame waited in the server behind other subscribers' sends. 0: not known
 * (nothing polled yet; a server that does not stamp writes). Any pointer
 * may be NULL. */
GMR_C_API gmr_status gmr_last_frame_times(gmr_subscription* subscription, int64_t* server_send_time_ns,
                                          int64_t* server_write_time_ns, int64_t* receive_time_ns);

/* Frames received, and of them replaced by a newer one before a poll or
 * dropped because they were not of the subscription's skeleton (a frame of a
 * new version that came before the change, or of the old one after it):
 * gmr_poll_frame only returns frames of the skeleton
 * gmr_subscription_joint describes at that poll. */
GMR_C_API gmr_status gmr_subscription_counts(gmr_subscription* subscription, uint64_t* received, uint64_t* replaced);

/* Live sources (a 'publish' token; docs/protocol.md, "Live sources"). A
 * publisher announces a skeleton whose channels are a pre-rotation (GMR)
 * motion's, then pushes one frame of channel values at a time: joint by
 * joint, each joint's channels in its listed order, rotations in degrees.
 * An all-roots source gives every joint parent -1 and position channels. */
typedef enum gmr_channel {
  GMR_CHANNEL_X_POSITION = 0,
  GMR_CHANNEL_Y_POSITION = 1,
  GMR_CHANNEL_Z_POSITION = 2,
  GMR_CHANNEL_X_ROTATION = 3,
  GMR_CHANNEL_Y_ROTATION = 4,
  GMR_CHANNEL_Z_ROTATION = 5
} gmr_channel;

typedef struct gmr_publish_joint {
  const char* name;
  int32_t parent;         /* index of an earlier joint; -1: a root */
  double offset[3];       /* from the parent (a root: its position) */
  uint32_t channel_count; /* 0 to 6 */
  gmr_channel channels[6];
} gmr_publish_joint;

/* The view's motion put on another humanoid rig (docs/retarget.md): the
 * rig's joints as for gmr_publish (parents first; offsets and channels as a
 * BVH's), and the channel values of a pose it stands in when its rest pose
 * does not (Character Creator rigs: their first frame; NULL, 0: the rest
 * pose). Roles come from the built-in namings. Subscriptions of the view then
 * get the rig's joints (gmr_frame.skeleton_changed on running ones). */
GMR_C_API gmr_status gmr_retarget(gmr_client* client, uint32_t view_id, const gmr_publish_joint* joints,
                                  size_t joint_count, const double* reference, size_t reference_count);

/* One entry of a role -> joint map (docs/retarget.md, "Maps"): role "hips",
 * "left_lower_arm", ...; joint a name of the skeleton it maps. */
typedef struct gmr_role_joint {
  const char* role;
  const char* joint;
} gmr_role_joint;

/* gmr_retarget with maps and the rig's unit: `rig_map` names the rig's joints
 * by role and `source_map` the source's (NULL, 0: the built-in namings); a map
 * that gives a role twice is refused. `metres_per_unit` is the rig's unit (the
 * view's after it, so conventions give metres; 0: the motion's). */
GMR_C_API gmr_status gmr_retarget_mapped(gmr_client* client, uint32_t view_id, const gmr_publish_joint* joints,
                                         size_t joint_count, const double* reference, size_t reference_count,
                                         const gmr_role_joint* rig_map, size_t rig_map_count,
                                         const gmr_role_joint* source_map, size_t source_map_count,
                                         double metres_per_unit);

/* Announces live motion `name`; *publication_id names it in the calls below. */
GMR_C_API gmr_status gmr_publish(gmr_client* client, const char* name, const gmr_publish_joint* joints,
                                 size_t joint_count, double frame_time, double metres_per_unit,
                                 uint32_t* publication_id);
/* Queues one frame (`count` values: the skeleton's channel count) without
 * waiting for the server. The server answers only a frame it refuses; that
 * answer is returned by the first call after it arrived (which may be the
 * refused frame's own call; the frame given to a later call is still sent). */
GMR_C_API gmr_status gmr_publish_frame(gmr_client* client, uint32_t publication_id, const double* values, size_t count);
/* Ends the source: its subscribers are told. */
GMR_C_API gmr_status gmr_unpublish(gmr_client* client, uint32_t publication_id);

#ifdef __cplusplus
}
#endif

#endif /* GMR_CLIENT_C_H */
