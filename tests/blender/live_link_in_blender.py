"""Runs inside Blender (blender -b --factory-startup --python THIS -- ARGS):
the gmr live link add-on, driven through its operators and its timer
function, against a gmr-server the driver (live_link_test.py) started.
Writes what the armature showed: every applied frame's bone heads in world
space, before and after a root change requested from Blender, and the heads
the recorded Action gives back. With --target-bvh: that rig imported by
Blender's own BVH importer is the selected armature the add-on retargets
onto; it writes its heads per frame and, per bone, how far the bone's pose
rotation misses turning its rest direction onto its child's head."""

import argparse
import json
import sys
import time

import bpy

argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
parser = argparse.ArgumentParser()
parser.add_argument("--addon-dir", required=True)
parser.add_argument("--python-dir", required=True)
parser.add_argument("--port", type=int, required=True)
parser.add_argument("--motion", required=True)
parser.add_argument("--roots", default="")
parser.add_argument("--viewpoint", default="")
parser.add_argument("--new-roots", required=True)
parser.add_argument("--frames", type=int, default=25)
parser.add_argument("--out", required=True)
parser.add_argument("--target-bvh", default="")
args = parser.parse_args(argv)

sys.path.insert(0, args.addon_dir)
sys.path.insert(0, args.python_dir)
import gmr_live_link  # noqa: E402

gmr_live_link.register()
scene = bpy.context.scene
scene.gmr.port = args.port
assert bpy.ops.gmr.connect() == {"FINISHED"}, gmr_live_link._status
scene.gmr.motion = args.motion
scene.gmr.roots = args.roots
scene.gmr.viewpoint = args.viewpoint
scene.gmr.record = True
if args.target_bvh:
    # The user's character: a rig Blender imported itself (with its default
    # axis conversion, Y up to Z up), selected, its own animation dropped so
    # only the live link moves it. Debian's Blender 3.4 importer opens files
    # with mode 'rU', which Python 3.11 rejects: its module gets an open()
    # without the 'U' (as tests/interop/blender_bvh_positions.py does).
    import builtins
    import io_anim_bvh.import_bvh as import_bvh
    import_bvh.open = lambda file, mode="r", *a, **k: builtins.open(file, mode.replace("U", ""), *a, **k)
    bpy.ops.object.select_all(action="DESELECT")
    assert bpy.ops.import_anim.bvh(filepath=args.target_bvh) == {"FINISHED"}
    character = bpy.context.view_layer.objects.active
    assert character is not None and character.type == "ARMATURE", "the BVH importer made no armature"
    character.animation_data_clear()
    scene.gmr.retarget = True
    scene.gmr.record = False
assert bpy.ops.gmr.start() == {"FINISHED"}, gmr_live_link._status
link = gmr_live_link._link


def heads():
    bpy.context.view_layer.update()
    obj = link.object
    return {pb.name: list(obj.matrix_world @ pb.head) for pb in obj.pose.bones}


def collect(count, version=None):
    """Runs the add-on's timer function until `count` frames (of `version`) were applied."""
    out = []
    last = None
    deadline = time.monotonic() + 60
    while len(out) < count:
        if time.monotonic() > deadline:
            raise SystemExit(f"only {len(out)} frames applied in 60 s ({gmr_live_link._status})")
        interval = gmr_live_link._tick()
        assert interval is not None, gmr_live_link._status
        f = link.last_frame
        if f is not None and f is not last and (version is None or f.skeleton_version == version):
            last = f
            out.append({"frame": f.frame_index, "version": f.skeleton_version,
                        "parents": {link.bone_names[j]: (link.bone_names[p] if p >= 0 else "")
                                    for j, p in enumerate(link.parents) if link.bone_names[j] is not None},
                        "heads": heads()})
        time.sleep(0.002)
    return out


before = collect(args.frames)
first_object = link.object.name

if args.target_bvh:
    # Skinning follows the bones' rotations, not their heads: each bone's pose
    # rotation (from its rest) must turn its rest direction to its first child
    # onto where that child's head is now.
    obj = link.object
    assert obj is character, "the add-on drove another armature than the selected one"
    misses = {}
    for pb in obj.pose.bones:
        if not pb.children:
            continue
        child = pb.children[0]
        rest = child.bone.head_local - pb.bone.head_local
        if rest.length < 1e-6:
            continue
        turn = pb.matrix.to_3x3() @ pb.bone.matrix_local.to_3x3().inverted()
        now = child.head - pb.head
        misses[pb.name] = (turn @ rest - now).length / rest.length
    # Streaming again without a target builds an armature of its own and
    # leaves the user's alone (twice: the second build removes the first).
    bones = len(obj.pose.bones)
    link.open(args.motion)
    link.open(args.motion)
    kept = character.name in bpy.data.objects and len(character.pose.bones) == bones
    json.dump({"before": before, "object": first_object, "rotation_misses": misses, "bones": bones,
               "character_kept": kept, "built": link.object.name}, open(args.out, "w"))
    link.close()
    print("live link: done")
    sys.exit(0)
# A root change from Blender: the server's skeleton changes, the armature follows.
scene.gmr.roots = args.new_roots
assert bpy.ops.gmr.apply_view() == {"FINISHED"}
new_version = None
deadline = time.monotonic() + 30
while new_version is None or link.sub.skeleton_version != new_version:
    gmr_live_link._tick()
    new_version = link.sub.skeleton_version if link.sub.skeleton_changes else None
    if time.monotonic() > deadline:
        raise SystemExit("no skeleton change arrived")
    time.sleep(0.002)
after = collect(args.frames, version=new_version)
roots_after = [link.bone_names[j] for j, p in enumerate(link.parents) if p < 0]

# The recorded Action: play it back with the stream stopped.
assert bpy.ops.gmr.stop() == {"FINISHED"}
action = link.object.animation_data.action if link.object.animation_data else None
played = []
if action is not None:
    for sample in after[:: max(1, len(after) // 8)]:
        scene.frame_set(sample["frame"] + 1)
        played.append({"frame": sample["frame"], "heads": heads()})

json.dump({"before": before, "after": after, "roots_after": roots_after, "versions": [before[0]["version"], new_version],
           "action_fcurves": len(action.fcurves) if action else 0, "recorded": link.recorded, "played": played,
           "bones": len(link.object.pose.bones)}, open(args.out, "w"))
link.close()
print("live link: done")
