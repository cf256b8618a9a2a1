"""The C ABI (libgmr_client_c.so, gmr_client_c.h) tested from a plain C
program and from Python ctypes, against a gmr-server started here: the
frames they poll equal `gmr positions` of the same frames and view; the
library exports only gmr_* and has its SONAME.

    c_abi_test.py --bin-dir build/bin --lib build/lib/libgmr_client_c.so --c-test build/tests/gmr_c_abi_test
"""

import argparse
import ctypes
import pathlib
import subprocess
import sys
import tempfile
import time

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "python"))
import gmr_test_env as env  # noqa: E402


class MotionInfo(ctypes.Structure):
    _fields_ = [("name", ctypes.c_char * 256), ("joint_count", ctypes.c_uint32), ("frame_count", ctypes.c_uint64),
                ("frame_time", ctypes.c_double), ("metres_per_unit", ctypes.c_double)]


class JointInfo(ctypes.Structure):
    _fields_ = [("name", ctypes.c_char * 128), ("parent", ctypes.c_int32), ("rest_translation", ctypes.c_double * 3),
                ("rest_rotation", ctypes.c_double * 4)]


class SubscribeOptions(ctypes.Structure):
    _fields_ = [("struct_size", ctypes.c_uint32), ("rate_hz", ctypes.c_double), ("speed", ctypes.c_double),
                ("loop", ctypes.c_int32), ("udp", ctypes.c_int32), ("float64", ctypes.c_int32),
                ("local_transforms", ctypes.c_int32), ("orientations", ctypes.c_int32),
                ("max_frames", ctypes.c_uint64), ("start_frame", ctypes.c_uint32), ("end_frame", ctypes.c_uint32),
                ("preset", ctypes.c_int), ("source_metres_per_unit", ctypes.c_double),
                ("max_staleness_ms", ctypes.c_uint32)]


class Frame(ctypes.Structure):
    _fields_ = [("frame_index", ctypes.c_uint64), ("motion_time", ctypes.c_double), ("sequence", ctypes.c_uint64),
                ("server_send_time_ns", ctypes.c_int64), ("skeleton_version", ctypes.c_uint32),
                ("joint_count", ctypes.c_uint32), ("skeleton_changed", ctypes.c_int32),
                ("has_local_transforms", ctypes.c_int32), ("has_orientations", ctypes.c_int32)]


class PublishJoint(ctypes.Structure):
    _fields_ = [("name", ctypes.c_char_p), ("parent", ctypes.c_int32), ("offset", ctypes.c_double * 3),
                ("channel_count", ctypes.c_uint32), ("channels", ctypes.c_int * 6)]


GMR_OK, GMR_NO_FRAME, GMR_ENDED, GMR_ERROR_NOT_FOUND = 0, 1, 2, 13
GMR_ERROR_BAD_REQUEST = 12
X_POSITION, Y_POSITION, Z_POSITION, Z_ROTATION = 0, 1, 2, 5
PRESET_BLENDER = 3


def load(path):
    lib = ctypes.CDLL(str(path))
    P = ctypes.c_void_p
    lib.gmr_last_error.restype = ctypes.c_char_p
    lib.gmr_connect.argtypes = [ctypes.c_char_p, ctypes.c_uint16, ctypes.c_char_p, ctypes.POINTER(P)]
    lib.gmr_disconnect.argtypes = [P]
    lib.gmr_list_motions.argtypes = [P, ctypes.POINTER(MotionInfo), ctypes.c_size_t, ctypes.POINTER(ctypes.c_size_t)]
    lib.gmr_create_view.argtypes = [P, ctypes.c_char_p, ctypes.POINTER(ctypes.c_uint32)]
    lib.gmr_set_roots.argtypes = [P, ctypes.c_uint32, ctypes.POINTER(ctypes.c_char_p), ctypes.c_size_t]
    lib.gmr_set_viewpoint.argtypes = [P, ctypes.c_uint32, ctypes.c_char_p]
    lib.gmr_subscribe_options_init.argtypes = [ctypes.POINTER(SubscribeOptions)]
    lib.gmr_subscribe.argtypes = [P, ctypes.c_uint32, ctypes.POINTER(SubscribeOptions), ctypes.POINTER(P)]
    lib.gmr_unsubscribe.argtypes = [P]
    lib.gmr_subscription_joint_count.argtypes = [P, ctypes.POINTER(ctypes.c_size_t)]
    lib.gmr_subscription_joint.argtypes = [P, ctypes.c_size_t, ctypes.POINTER(JointInfo)]
    D = ctypes.POINTER(ctypes.c_double)
    lib.gmr_poll_frame.argtypes = [P, ctypes.POINTER(Frame), D, D, D, D, ctypes.c_size_t]
    lib.gmr_publish.argtypes = [P, ctypes.c_char_p, ctypes.POINTER(PublishJoint), ctypes.c_size_t, ctypes.c_double,
                                ctypes.c_double, ctypes.POINTER(ctypes.c_uint32)]
    lib.gmr_publish_frame.argtypes = [P, ctypes.c_uint32, D, ctypes.c_size_t]
    lib.gmr_unpublish.argtypes = [P, ctypes.c_uint32]
    lib.gmr_split.argtypes = [P, ctypes.c_uint32, ctypes.c_char_p]
    lib.gmr_join.argtypes = [P, ctypes.c_uint32, ctypes.c_char_p]
    return lib


def check_skeleton_changes(lib, port, udp, failures):
    """A view edited 40 times (split and join back at the left knee) while a
    1 kHz subscription streams it: every polled frame belongs to the skeleton
    the subscription reports at that poll. A frame of a new version that
    overtakes the change (UDP), or one of the old version still queued behind
    it (TCP), is never handed out: the version of polled frames only changes
    on a poll that says the skeleton changed, and then only upwards."""
    label = "UDP" if udp else "TCP"
    client = ctypes.c_void_p()
    assert lib.gmr_connect(b"127.0.0.1", port, None, ctypes.byref(client)) == GMR_OK, lib.gmr_last_error()
    view = ctypes.c_uint32()
    assert lib.gmr_create_view(client, b"walk", ctypes.byref(view)) == GMR_OK, lib.gmr_last_error()
    o = SubscribeOptions()
    lib.gmr_subscribe_options_init(ctypes.byref(o))
    o.loop, o.udp, o.rate_hz, o.local_transforms = 1, udp, 1000.0, 1
    sub = ctypes.c_void_p()
    assert lib.gmr_subscribe(client, view, ctypes.byref(o), ctypes.byref(sub)) == GMR_OK, lib.gmr_last_error()
    positions = (ctypes.c_double * (3 * 64))()
    rotations = (ctypes.c_double * (4 * 64))()
    frame = Frame()
    version, polled, changes, problems = None, 0, 0, []

    def poll_for(seconds):
        nonlocal version, polled, changes
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            s = lib.gmr_poll_frame(sub, ctypes.byref(frame), positions, None, rotations, None, 64)
            if s == GMR_NO_FRAME:
                time.sleep(0.0005)
                continue
            assert s == GMR_OK, lib.gmr_last_error()
            polled += 1
            n = ctypes.c_size_t()
            lib.gmr_subscription_joint_count(sub, ctypes.byref(n))
            if frame.joint_count != n.value:
                problems.append(f"a frame of {frame.joint_count} joints for a skeleton of {n.value}")
            if version is None or frame.skeleton_changed:
                if version is not None and frame.skeleton_version <= version:
                    problems.append(f"skeleton changed to version {frame.skeleton_version} after {version}")
                changes += version is not None
                version = frame.skeleton_version
            elif frame.skeleton_version != version:
                problems.append(f"a frame of version {frame.skeleton_version} polled under version {version}")

    poll_for(0.1)
    for k in range(40):
        edit = lib.gmr_split if k % 2 == 0 else lib.gmr_join
        assert edit(client, view, b"l_knee") == GMR_OK, lib.gmr_last_error()
        poll_for(0.02)
    poll_for(0.2)
    if problems or polled < 100 or changes == 0:
        failures.append(f"C ABI skeleton changes over {label}: {polled} frames polled, {changes} changes seen, "
                        f"{len(problems)} problems: {problems[:5]}")
    print(f"C ABI skeleton changes over {label}: {polled} frames polled across {changes} changes seen, "
          "each under its own skeleton")
    lib.gmr_unsubscribe(sub)
    lib.gmr_disconnect(client)


def check_publish(lib, port, failures):
    """A two-joint live source published through the C ABI: a root with
    position channels and a child rotating about Z (pre-rotation: its
    rotation turns its own offset). A subscriber polls exactly the positions
    worked out by hand; a frame with a NaN or the wrong count is refused."""
    pub, viewer = ctypes.c_void_p(), ctypes.c_void_p()
    assert lib.gmr_connect(b"127.0.0.1", port, None, ctypes.byref(pub)) == GMR_OK, lib.gmr_last_error()
    assert lib.gmr_connect(b"127.0.0.1", port, None, ctypes.byref(viewer)) == GMR_OK, lib.gmr_last_error()
    joints = (PublishJoint * 2)()
    joints[0].name, joints[0].parent, joints[0].channel_count = b"base", -1, 3
    joints[0].channels[:3] = [X_POSITION, Y_POSITION, Z_POSITION]
    joints[1].name, joints[1].parent, joints[1].channel_count = b"tip", 0, 1
    joints[1].offset[:] = [1.0, 0.0, 0.0]
    joints[1].channels[0] = Z_ROTATION
    pid = ctypes.c_uint32()
    s = lib.gmr_publish(pub, b"cabi/live", joints, 2, 1 / 60, 1.0, ctypes.byref(pid))
    if s != GMR_OK:
        failures.append(f"gmr_publish: {s} {lib.gmr_last_error()}")
        return
    view = ctypes.c_uint32()
    assert lib.gmr_create_view(viewer, b"cabi/live", ctypes.byref(view)) == GMR_OK, lib.gmr_last_error()
    o = SubscribeOptions()
    lib.gmr_subscribe_options_init(ctypes.byref(o))
    o.float64 = 1
    sub = ctypes.c_void_p()
    assert lib.gmr_subscribe(viewer, view, ctypes.byref(o), ctypes.byref(sub)) == GMR_OK, lib.gmr_last_error()
    positions = (ctypes.c_double * 6)()
    frame = Frame()
    worst, polled = 0.0, set()
    for k in range(20):
        values = (ctypes.c_double * 4)(float(k), 2.0, 3.0, 90.0)
        assert lib.gmr_publish_frame(pub, pid, values, 4) == GMR_OK, lib.gmr_last_error()
        deadline = time.monotonic() + 5
        while time.monotonic() < deadline:
            s = lib.gmr_poll_frame(sub, ctypes.byref(frame), positions, None, None, None, 2)
            if s == GMR_OK:
                i = frame.frame_index
                want = [i, 2.0, 3.0, i, 3.0, 3.0]  # tip = base + Rz(90) (1, 0, 0)
                worst = max(worst, *(abs(positions[n] - want[n]) for n in range(6)))
                polled.add(i)
                if i == k:
                    break
            time.sleep(0.002)
    if polled != set(range(20)) or worst > 1e-12:
        failures.append(f"C ABI publish: polled frames {sorted(polled)}, {worst:.3g} from the hand-made positions")
    print(f"C ABI publish: {len(polled)} live frames polled at the hand-made positions (largest difference {worst:.3g})")
    # A refused frame's error comes back with a later call, or with the same
    # one when the server answered before it returned.
    said = []
    nan = (ctypes.c_double * 4)(0.0, float("nan"), 0.0, 0.0)
    said.append((lib.gmr_publish_frame(pub, pid, nan, 4), lib.gmr_last_error()))
    for k in range(25):  # good frames until the answer came (5 s at most)
        if said[-1][0] != GMR_OK:
            break
        time.sleep(0.2)
        said.append((lib.gmr_publish_frame(pub, pid, (ctypes.c_double * 4)(20.0 + k, 2.0, 3.0, 90.0), 4),
                     lib.gmr_last_error()))
    refused = [(s, e) for s, e in said if s != GMR_OK]
    if len(refused) != 1 or refused[0][0] != GMR_ERROR_BAD_REQUEST or b"not finite" not in (refused[0][1] or b""):
        failures.append(f"C ABI publish: a NaN frame gave {said}")
    assert lib.gmr_unpublish(pub, pid) == GMR_OK, lib.gmr_last_error()
    deadline = time.monotonic() + 5
    while lib.gmr_poll_frame(sub, ctypes.byref(frame), positions, None, None, None, 2) != GMR_ENDED:
        if time.monotonic() > deadline:
            failures.append("C ABI publish: the subscription did not end with the source")
            break
        time.sleep(0.005)
    lib.gmr_unsubscribe(sub)
    lib.gmr_disconnect(viewer)
    lib.gmr_disconnect(pub)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--bin-dir", required=True)
    ap.add_argument("--lib", required=True)
    ap.add_argument("--c-test", required=True)
    args = ap.parse_args()
    bin_dir = pathlib.Path(args.bin_dir)
    failures = []

    # Only gmr_* leaves the library, and it has its SONAME.
    symbols = subprocess.run(["nm", "-D", "--defined-only", args.lib], check=True, capture_output=True,
                             text=True).stdout.split()
    exported = [s for s in symbols[2::3]]
    if not exported or any(not s.startswith("gmr_") for s in exported):
        failures.append(f"exported symbols other than gmr_*: {[s for s in exported if not s.startswith('gmr_')][:10]}")
    dynamic = subprocess.run(["readelf", "-d", args.lib], check=True, capture_output=True, text=True).stdout
    if "Library soname: [libgmr_client_c.so.0]" not in dynamic:
        failures.append("no SONAME libgmr_client_c.so.0")

    with tempfile.TemporaryDirectory(prefix="gmr_cabi_") as tmp:
        subprocess.run([str(bin_dir / "gmr"), "demo", tmp, "--format", "gmr"], check=True, capture_output=True)
        walk = pathlib.Path(tmp) / "walk.gmr"
        with env.Server(bin_dir, "--anonymous", "publish") as server:
            # The C program.
            run = subprocess.run([args.c_test, str(server.port)], capture_output=True, text=True, timeout=120)
            if run.returncode != 0:
                failures.append(f"the C program failed ({run.returncode}): {run.stderr}")
            else:
                print(run.stderr.strip())
                want, names = env.gmr_positions(bin_dir, walk, "--roots", "head", "--conventions", "unity",
                                                "--metres-per-unit", "0.01")
                index = {n: i for i, n in enumerate(names)}
                worst, rows = 0.0, 0
                for line in run.stdout.splitlines():
                    _, frame, name, x, y, z = line.split()  # "frame ..." (polled) and "query ..." lines
                    w = want[int(frame)][index[name]]
                    worst = max(worst, abs(float(x) - w[0]), abs(float(y) - w[1]), abs(float(z) - w[2]))
                    rows += 1
                if rows < 5 * 22 or worst > 1e-9:
                    failures.append(f"C: {rows} positions, {worst:.3g} from gmr positions")
                print(f"C program: {rows} joint positions equal gmr positions (largest difference {worst:.3g} m)")

            # Python ctypes.
            lib = load(args.lib)
            client = ctypes.c_void_p()
            if lib.gmr_connect(b"127.0.0.1", server.port, None, ctypes.byref(client)) != GMR_OK:
                failures.append(f"ctypes connect: {lib.gmr_last_error()}")
            else:
                motions = (MotionInfo * 8)()
                count = ctypes.c_size_t()
                lib.gmr_list_motions(client, motions, 8, ctypes.byref(count))
                listed = sorted(motions[i].name.decode() for i in range(count.value))
                if listed != ["jump", "turn", "walk", "wave"]:
                    failures.append(f"ctypes list: {listed}")
                view = ctypes.c_uint32()
                assert lib.gmr_create_view(client, b"walk", ctypes.byref(view)) == GMR_OK
                roots = (ctypes.c_char_p * 2)(b"l_hand", b"r_toe")
                assert lib.gmr_set_roots(client, view, roots, 2) == GMR_OK, lib.gmr_last_error()
                assert lib.gmr_set_viewpoint(client, view, b"pelvis") == GMR_OK, lib.gmr_last_error()
                o = SubscribeOptions()
                lib.gmr_subscribe_options_init(ctypes.byref(o))
                o.preset = PRESET_BLENDER
                o.float64 = 1
                o.end_frame = 40
                o.speed = 4
                sub = ctypes.c_void_p()
                assert lib.gmr_subscribe(client, view, ctypes.byref(o), ctypes.byref(sub)) == GMR_OK, lib.gmr_last_error()
                n = ctypes.c_size_t()
                lib.gmr_subscription_joint_count(sub, ctypes.byref(n))
                joint_names = []
                for j in range(n.value):
                    info = JointInfo()
                    lib.gmr_subscription_joint(sub, j, ctypes.byref(info))
                    joint_names.append(info.name.decode())
                want, names = env.gmr_positions(bin_dir, walk, "--roots", "l_hand,r_toe", "--relative-to", "pelvis",
                                                "--conventions", "blender", "--metres-per-unit", "0.01")
                positions = (ctypes.c_double * (3 * 64))()
                frame = Frame()
                polled, worst = 0, 0.0
                deadline = time.monotonic() + 30
                while time.monotonic() < deadline:
                    s = lib.gmr_poll_frame(sub, ctypes.byref(frame), positions, None, None, None, 64)
                    if s == GMR_ENDED:
                        break
                    if s == GMR_NO_FRAME:
                        time.sleep(0.002)
                        continue
                    assert s == GMR_OK, lib.gmr_last_error()
                    for j, name in enumerate(joint_names):
                        w = want[frame.frame_index][names.index(name)]
                        worst = max(worst, *(abs(positions[3 * j + k] - w[k]) for k in range(3)))
                    polled += 1
                if polled < 5 or worst > 1e-9:
                    failures.append(f"ctypes: {polled} frames polled, {worst:.3g} from gmr positions")
                print(f"ctypes: {polled} frames polled equal gmr positions (largest difference {worst:.3g} m)")
                lib.gmr_unsubscribe(sub)
                none = ctypes.c_uint32()
                s = lib.gmr_create_view(client, b"nope", ctypes.byref(none))
                if s != GMR_ERROR_NOT_FOUND or b"nope" not in lib.gmr_last_error():
                    failures.append(f"ctypes error path: {s} {lib.gmr_last_error()}")
                lib.gmr_disconnect(client)
                check_publish(lib, server.port, failures)
                for udp in (0, 1):
                    check_skeleton_changes(lib, server.port, udp, failures)

    if failures:
        print("\n".join(failures), file=sys.stderr)
        sys.exit(1)
    print(f"C ABI: {len(exported)} exported functions, all gmr_*")


if __name__ == "__main__":
    main()
