# Runs inside Blender: imports BVH files with Blender's own importer
# (io_anim_bvh) and writes every bone's world position in every frame.
#
#   blender -b --factory-startup --python blender_bvh_positions.py -- MANIFEST.json
#
# MANIFEST.json: [{"bvh": "in.bvh", "out": "positions.csv", "frames": N,
#                  "mode": "NATIVE" | "QUATERNION" | ...}, ...]
# "mode" is the importer's rotation mode (default NATIVE: Euler in the file's
# order). The importer keys file frame k at scene frame 1 + k. Each CSV has the
# lines of `gmr positions`: frame,joint,x,y,z, frames from 0, in world space,
# imported with Blender's own axes as the file's (forward Y, up Z: no axis
# conversion). A bone's head is the joint; a bone whose
# BVH block ends in an End Site also gets a line "joint@tail": Blender's tail,
# which the importer puts on that End Site.
#
# The one change to Blender: Debian's Blender 3.4 importer opens files with
# mode 'rU', which Python 3.11 rejects; this script gives the importer module
# an open() that drops the 'U'. The BVH files are read as they are.
import builtins
import json
import sys

import bpy
import io_anim_bvh.import_bvh as import_bvh


def _open_without_u(file, mode="r", *args, **kwargs):
    return builtins.open(file, mode.replace("U", ""), *args, **kwargs)


import_bvh.open = _open_without_u


def positions(bvh_path, out_path, frames, mode):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    result = bpy.ops.import_anim.bvh(
        filepath=bvh_path,
        global_scale=1.0,
        frame_start=1,
        use_fps_scale=False,
        update_scene_fps=False,
        update_scene_duration=False,
        use_cyclic=False,
        rotate_mode=mode,
        # Blender's own axes: no conversion, so positions stay in the file's axes.
        axis_forward="Y",
        axis_up="Z",
    )
    if "FINISHED" not in result:
        raise RuntimeError(f"Blender did not import {bvh_path}: {result}")
    arm = next(o for o in bpy.context.scene.objects if o.type == "ARMATURE")
    scene = bpy.context.scene
    bones = list(arm.pose.bones)
    with open(out_path, "w") as out:
        out.write("frame,joint,x,y,z\n")
        for f in range(frames):
            scene.frame_set(1 + f)
            rows = []
            world = arm.matrix_world
            for b in bones:
                h = world @ b.head
                rows.append(f"{f},{b.name},{h.x!r},{h.y!r},{h.z!r}\n")
                t = world @ b.tail
                rows.append(f"{f},{b.name}@tail,{t.x!r},{t.y!r},{t.z!r}\n")
            out.write("".join(rows))
    return frames


def main():
    manifest = json.load(open(sys.argv[sys.argv.index("--") + 1]))
    failed = 0
    for item in manifest:
        try:
            n = positions(item["bvh"], item["out"], item["frames"], item.get("mode", "NATIVE"))
            print(f"blender-bvh: {item['bvh']}: {n} frames", flush=True)
        except Exception as e:  # report and go on: the test names what failed
            failed += 1
            print(f"blender-bvh: {item['bvh']}: FAILED: {e!r}", flush=True)
    sys.exit(1 if failed else 0)


main()
