"""The live link without the UI: a subscription to a gmr-server view that
drives an armature, in Blender's conventions (Z up, -Y forward, metres).

The armature is built from the skeleton the subscription carries: one bone
per joint, its head at the joint's rest position, its tail toward the child
that gives the joint its frame (docs/protocol.md, "Local transforms and rest
pose"). Each frame's local transforms are composed from the roots down into
every joint's frame O_j and position P_j, and each pose bone gets the
transform that puts its head at P_j turned by O_j from its rest:

    pose_j = [O_j A_j | P_j]      (A_j: the bone's rest orientation)
    matrix_basis_j = rest_j^-1 rest_p pose_p^-1 pose_j   (rest_j^-1 pose_j for a root)

With a target armature (the user's own character), the server retargets
the view onto it (docs/retarget.md) and the frames drive that armature's
bones instead: `armature_rig` sends its bones as the rig, in the motion's
axes and the armature's unit, and the subscription asks for the armature's
own space back, so the pose bones take the same formula with their own rest
matrices (and their own parents, should the server's hierarchy differ).

`tick()` never blocks: it reads what has arrived and applies the newest
frame. The add-on runs it on a bpy.app.timers timer; a script can call it.
"""

import time

import bpy
import numpy as np
from mathutils import Matrix, Quaternion, Vector

import gmr_client


def _own_frame_children(parents):
    """For each joint, the child whose bone gives it its frame (largest subtree, first on a tie), or -1."""
    n = len(parents)
    subtree = [1] * n
    for j in range(n - 1, -1, -1):
        if parents[j] >= 0:
            subtree[parents[j]] += subtree[j]
    best = [-1] * n
    for j in range(n):
        p = parents[j]
        if p >= 0 and (best[p] < 0 or subtree[j] > subtree[best[p]]):
            best[p] = j
    return best


# Blender's axes (Z up, -Y forward) to the motion's (Y up, +Z forward): the
# inverse of the "blender" conventions (x, y, z) -> (x, -z, y).
def _to_motion_axes(v):
    return (v[0], v[2], -v[1])


def armature_rig(obj):
    """The armature `obj` as a gmr rig for Client.retarget: one joint per bone
    (parents first), each bone's head relative to its parent's head in the
    armature's space turned into the motion's axes, BVH channels, and the unit
    of the armature's space in metres (its object scale times the scene's unit
    scale). A bone without children also ends in a joint at its tail, named
    "<bone>_End" without channels: a BVH's End Site, where Blender's importer
    puts that tail, and what gmr's roles `head_end` and `toes_end` (and the
    rig's hip height, over its lowest toe) read. Returns (Skeleton,
    metres_per_unit)."""
    if obj is None or obj.type != "ARMATURE":
        raise ValueError("select an armature to retarget onto")
    scale = obj.matrix_world.to_scale()
    if max(scale) - min(scale) > 1e-6 * max(scale) or min(scale) <= 0:
        raise ValueError(f"armature '{obj.name}' is scaled unevenly ({tuple(round(s, 6) for s in scale)}): "
                         "apply its scale first")
    unit = float(scale[0]) * float(bpy.context.scene.unit_settings.scale_length or 1.0)
    order = []

    def visit(bone):
        order.append(bone)
        for c in bone.children:
            visit(c)
    for b in obj.data.bones:
        if b.parent is None:
            visit(b)
    if not order:
        raise ValueError(f"armature '{obj.name}' has no bones")
    index = {}  # bone name -> joint index (the tips' joints come between bones)
    names, parents, offsets, channels = [], [], [], []
    rot = ["Zrotation", "Xrotation", "Yrotation"]
    for b in order:
        p = index[b.parent.name] if b.parent else -1
        head = b.head_local - (b.parent.head_local if b.parent else Vector((0.0, 0.0, 0.0)))
        index[b.name] = len(names)
        names.append(b.name)
        parents.append(p)
        offsets.append(_to_motion_axes(head))
        channels.append((["Xposition", "Yposition", "Zposition"] + rot) if p < 0 else rot)
        if not b.children and f"{b.name}_End" not in obj.data.bones:
            names.append(f"{b.name}_End")
            parents.append(len(names) - 2)
            offsets.append(_to_motion_axes(b.tail_local - b.head_local))
            channels.append([])
    n = len(names)
    sk = gmr_client.Skeleton(names, np.array(parents, dtype=np.int32), np.full(n, -1, dtype=np.int32),
                             np.array(offsets, dtype=np.float64), channels, np.zeros((n, 3)),
                             np.tile([0.0, 0.0, 0.0, 1.0], (n, 1)))
    return sk, unit


class LiveLink:
    def __init__(self, host="127.0.0.1", port=gmr_client.DEFAULT_PORT, token="", name="blender"):
        self.client = gmr_client.Client(host, port, name=name, token=token)
        self.view = None
        self.sub = None
        self.object = None
        self.version = None      # skeleton version the armature was built for
        self.frames_applied = 0
        self.last_frame = None   # the gmr Frame applied last
        self.record = False      # insert keyframes into the armature's Action
        self.recorded = 0
        self._rest = []          # per joint: the bone's rest matrix (armature space)
        self.target = None       # the user's armature the view is retargeted onto, or None
        self._built = None       # the armature build_armature made last (removed when it makes another)

    # ------------------------------------------------------------ set-up

    def motions(self):
        return self.client.list_motions()

    def open(self, motion, roots=(), viewpoint="", rate_hz=0.0, speed=1.0, loop=True, udp=False, max_frames=0,
             target=None):
        """A view of `motion` with these roots and viewpoint, a subscription in
        Blender's conventions with local transforms, and its armature: one
        built from the view's skeleton, or `target` (an armature object), the
        user's character the server retargets the view onto (no viewpoint:
        the retargeted motion is in world coordinates)."""
        self.close_stream()
        if target is not None and viewpoint:
            raise ValueError("a retargeted view is seen in world coordinates: clear the viewpoint")
        rig = armature_rig(target) if target is not None else None
        self.view = self.client.create_view(motion)
        if roots:
            self.client.set_roots(self.view.id, list(roots))
        if viewpoint:
            self.client.set_coordinates(self.view.id, viewpoint)
        conventions = "blender"
        if rig is not None:
            self.client.retarget(self.view.id, rig[0], metres_per_unit=rig[1])
            # Frames in the armature's own space: Blender's axes, its unit.
            conventions = gmr_client.Conventions(preset="custom", up=3, forward=-2, target_metres_per_unit=rig[1])
        self.sub = self.client.subscribe(self.view.id, loop=loop, rate_hz=rate_hz, speed=speed, udp=udp,
                                         local_transforms=True, float64=True, max_frames=max_frames,
                                         conventions=conventions, max_staleness_ms=100)  # live: fresh frames only
        self.target = target
        if target is not None:
            self.bind_armature(target)
        else:
            self.build_armature(motion)
        return self.object

    def set_roots(self, roots):
        """Asks the server for other roots; the new skeleton comes on the subscription and the armature follows."""
        return self.client.set_roots(self.view.id, list(roots))

    def set_viewpoint(self, joint):
        return self.client.set_coordinates(self.view.id, joint)

    def close_stream(self):
        if self.sub is not None and self.sub.ended is None:
            try:
                self.sub.unsubscribe()
            except gmr_client.GmrError:
                pass
        if self.view is not None:
            try:
                self.client.close_view(self.view.id)
            except gmr_client.GmrError:
                pass
        self.sub = None
        self.view = None

    def close(self):
        self.close_stream()
        self.client.close()

    # ------------------------------------------------------------ the armature

    def build_armature(self, name):
        """(Re)builds the armature from the subscription's skeleton and rest pose."""
        sk = self.sub.skeleton
        n = len(sk)
        parents = [int(p) for p in sk.parents]
        rest = [None] * n
        for j in range(n):  # rest positions: the rest translations composed (rest rotations are engine-local)
            q = Quaternion((sk.rest_rotations[j][3], *sk.rest_rotations[j][:3]))
            t = Vector(sk.rest_translations[j])
            if parents[j] < 0:
                rest[j] = (q.to_matrix(), t)
            else:
                o, p = rest[parents[j]]
                rest[j] = (o @ q.to_matrix(), p + o @ t)
        heads = [r[1] for r in rest]
        size = max([(h - heads[0]).length for h in heads] + [1e-3])
        child = _own_frame_children(parents)

        # A new skeleton starts a new Action (the old one stays in the file:
        # its keys belong to the old bones' hierarchy). Only an armature this
        # link built is removed, never the user's own (a retarget target).
        old = self._built
        if old is not None:
            try:
                data = old.data
                bpy.data.objects.remove(old, do_unlink=True)
                bpy.data.armatures.remove(data)
            except ReferenceError:
                pass  # the user deleted it already
        arm = bpy.data.armatures.new(f"gmr {name}")
        obj = bpy.data.objects.new(f"gmr {name}", arm)
        bpy.context.scene.collection.objects.link(obj)
        bpy.context.view_layer.objects.active = obj
        bpy.ops.object.mode_set(mode="EDIT")
        bones = []
        for j in range(n):
            b = arm.edit_bones.new(sk.names[j][:63])
            b.head = heads[j]
            tail = heads[child[j]] if child[j] >= 0 else None
            if tail is None or (tail - heads[j]).length < 1e-4 * size:
                # A leaf, or a zero-length bone: a short bone along the incoming
                # direction (or up), so Blender keeps it.
                p = parents[j]
                d = heads[j] - heads[p] if p >= 0 else Vector((0.0, 0.0, 1.0))
                d = d.normalized() if d.length > 1e-9 * size else Vector((0.0, 0.0, 1.0))
                tail = heads[j] + 0.05 * size * d
            b.tail = tail
            b.use_connect = False
            if parents[j] >= 0:
                b.parent = bones[parents[j]]
            bones.append(b)
        names = [b.name for b in bones]  # by joint index (arm.bones has its own order)
        bpy.ops.object.mode_set(mode="OBJECT")
        self.bone_names = names
        self._rest = [arm.bones[name].matrix_local.copy() for name in self.bone_names]
        for pb in obj.pose.bones:
            pb.rotation_mode = "QUATERNION"
        self.object = obj
        self._built = obj
        self.version = self.sub.skeleton_version
        self.parents = parents
        self.bone_parents = parents
        return obj

    def bind_armature(self, obj):
        """Drives the user's armature `obj`: every joint of the subscription's
        skeleton is one of its bones (the rig it was retargeted onto)."""
        sk = self.sub.skeleton
        bones = obj.data.bones
        # Every joint is a bone, or the tip of a bone without children that
        # armature_rig added (nothing to pose).
        tips = {f"{b.name}_End" for b in bones if not b.children}
        missing = [name for name in sk.names if name not in bones and name not in tips]
        if missing:
            raise RuntimeError(f"armature '{obj.name}' has no bones {', '.join(missing[:5])}: "
                               "the view is not on this armature")
        index = {name: j for j, name in enumerate(sk.names)}
        self.bone_names = [name if name in bones else None for name in sk.names]
        self.parents = [int(p) for p in sk.parents]
        self.bone_parents = [index[bones[name].parent.name] if name in bones and bones[name].parent
                             and bones[name].parent.name in index else -1 for name in sk.names]
        self._rest = [bones[name].matrix_local.copy() if name in bones else Matrix.Identity(4) for name in sk.names]
        for pb in obj.pose.bones:
            pb.rotation_mode = "QUATERNION"
        self.object = obj
        self.version = self.sub.skeleton_version
        return obj

    # ------------------------------------------------------------ frames

    def tick(self):
        """Applies the newest frame that arrived (never waits). Returns the
        gmr frame applied, or None. The add-on's timer calls it."""
        if self.sub is None:
            return None
        frame = self.sub.latest()
        if frame is None:
            return None
        if frame.skeleton_version != self.version:
            if frame.skeleton_version != self.sub.skeleton_version:
                return None  # a frame of a skeleton not announced yet (UDP can overtake): skip it
            if self.target is not None:
                self.bind_armature(self.target)
            else:
                self.build_armature(self.view.motion if self.view else "motion")
        self.apply(frame)
        return frame

    def apply(self, frame):
        n = len(self.parents)
        joints = [int(j) for j in self.sub.joints]
        if len(joints) != n or frame.local_rotations is None:
            raise RuntimeError("the live link needs every joint's local transforms")
        own = [None] * n
        pos = [None] * n
        by_joint = {j: i for i, j in enumerate(joints)}  # values follow `joints`; parents come first by index
        for j in range(n):
            i = by_joint[j]
            r = frame.local_rotations[i]
            q = Quaternion((r[3], r[0], r[1], r[2])).to_matrix()
            t = Vector(frame.local_translations[i])
            p = self.parents[j]
            if p < 0:
                own[j], pos[j] = q, t
            else:
                own[j], pos[j] = own[p] @ q, pos[p] + own[p] @ t
        pose = []
        for j in range(n):
            rest = self._rest[j]
            m = (own[j] @ rest.to_3x3()).to_4x4()
            m.translation = pos[j]
            pose.append(m)
        bones = self.object.pose.bones
        for j in range(n):
            if self.bone_names[j] is None:
                continue  # a bone's tip (armature_rig), not a bone
            p = self.bone_parents[j]  # the armature's parent (a retarget target keeps its own hierarchy)
            rest_j_inv = self._rest[j].inverted()
            if p < 0:
                basis = rest_j_inv @ pose[j]
            else:
                basis = rest_j_inv @ self._rest[p] @ pose[p].inverted() @ pose[j]
            pb = bones[self.bone_names[j]]
            loc, rot, _ = basis.decompose()
            pb.location = loc
            pb.rotation_quaternion = rot
            if self.record:
                key = frame.frame_index + 1
                pb.keyframe_insert("location", frame=key, group=pb.name)
                pb.keyframe_insert("rotation_quaternion", frame=key, group=pb.name)
        if self.record:
            self.recorded += 1
        self.frames_applied += 1
        self.last_frame = frame
        self.last_apply_time = time.monotonic()
