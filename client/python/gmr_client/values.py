"""The values the gmr client hands out and takes: skeletons, conventions,
views, query results, frames, and the error it raises."""

import dataclasses
import time
from typing import List, Optional, Sequence, Union

import numpy as np

from . import stream_pb2 as pb

_CHANNELS = ["Xposition", "Yposition", "Zposition", "Xrotation", "Yrotation", "Zrotation"]


class GmrError(Exception):
    """A refusal from the server (`code` is its name, e.g. "NOT_FOUND"), or a
    broken connection or malformed message (`code` "CONNECTION" or "PROTOCOL")."""

    def __init__(self, code: str, message: str):
        super().__init__(f"{code}: {message}")
        self.code = code
        self.message = message


PRESETS = {"native": 0, "unreal": 1, "unity": 2, "blender": 3, "godot": 4, "custom": 5}


@dataclasses.dataclass
class Conventions:
    """An engine's axes, handedness and unit (docs/protocol.md, "Conventions").

    preset: "native", "unreal", "unity", "blender", "godot" or "custom".
    For "custom": signed axes (1 = +X, 2 = +Y, 3 = +Z, -1 = -X, ...), handedness
    and the target's unit in metres. source_metres_per_unit: the motion's unit
    (0: the library's, or none).
    """

    preset: str = "native"
    up: int = 2
    forward: int = 3
    left_handed: bool = False
    target_metres_per_unit: float = 0.0
    source_metres_per_unit: float = 0.0

    def to_proto(self, out) -> None:
        if self.preset not in PRESETS:
            raise ValueError(f"unknown conventions preset '{self.preset}' (one of {', '.join(PRESETS)})")
        out.preset = PRESETS[self.preset]
        if self.preset == "custom":
            out.up = self.up
            out.forward = self.forward
            out.left_handed = self.left_handed
            out.target_metres_per_unit = self.target_metres_per_unit
        out.source_metres_per_unit = self.source_metres_per_unit


ConventionsLike = Union[None, str, Conventions]


def _set_conventions(conventions: ConventionsLike, out) -> None:
    if conventions is None:
        return
    if isinstance(conventions, str):
        conventions = Conventions(preset=conventions)
    conventions.to_proto(out)


@dataclasses.dataclass
class Skeleton:
    """Joints in index order, parents before children. The rest pose is each
    joint's translation and rotation (x, y, z, w) relative to its parent's
    frame (roots: to the world) with every channel zero, as engine bones."""

    names: List[str]
    parents: np.ndarray        # (n,) int, -1 for a root
    soft_parents: np.ndarray   # (n,) int, roots only: the parent a split removed; -1 if none
    offsets: np.ndarray        # (n, 3)
    channels: List[List[str]]  # per joint, BVH channel names in order
    rest_translations: np.ndarray  # (n, 3)
    rest_rotations: np.ndarray     # (n, 4) x, y, z, w

    def __len__(self) -> int:
        return len(self.names)

    def index(self, name: str) -> int:
        try:
            return self.names.index(name)
        except ValueError:
            raise KeyError(f"no joint '{name}' in this skeleton") from None

    @property
    def roots(self) -> List[int]:
        return [j for j, p in enumerate(self.parents) if p < 0]

    @property
    def channel_count(self) -> int:
        """Channel values per frame of a motion on this skeleton."""
        return sum(len(c) for c in self.channels)

    @staticmethod
    def points(names: Sequence[str]) -> "Skeleton":
        """Every joint a root with Xposition Yposition Zposition: a motion of
        world positions (what a marker or tracker system gives), to publish."""
        n = len(names)
        return Skeleton(list(names), np.full(n, -1, dtype=np.int32), np.full(n, -1, dtype=np.int32),
                        np.zeros((n, 3)), [_CHANNELS[:3] for _ in range(n)], np.zeros((n, 3)),
                        np.tile([0.0, 0.0, 0.0, 1.0], (n, 1)))

    def to_proto(self, out) -> None:
        """Writes names, parents, soft parents, offsets and channels into a
        stream_pb2.Skeleton (the rest pose is the server's to give)."""
        out.Clear()
        offsets = np.asarray(self.offsets, dtype=np.float64).reshape(len(self.names), 3)
        for j, name in enumerate(self.names):
            m = out.joints.add()
            m.name = name
            m.parent = int(self.parents[j])
            m.soft_parent = int(self.soft_parents[j]) if len(self.soft_parents) else -1
            m.offset.x, m.offset.y, m.offset.z = (float(v) for v in offsets[j])
            for c in self.channels[j]:
                if c not in _CHANNELS:
                    raise ValueError(f"joint '{name}': unknown channel '{c}' (one of {', '.join(_CHANNELS)})")
                m.channels.append(_CHANNELS.index(c))

    @staticmethod
    def from_proto(m) -> "Skeleton":
        n = len(m.joints)
        names = [j.name for j in m.joints]
        parents = np.array([j.parent for j in m.joints], dtype=np.int32)
        for j, p in enumerate(parents):
            if not -1 <= p < j:
                raise GmrError("PROTOCOL", f"joint {j} ('{names[j]}') has parent {p}: parents come before children")
        offsets = np.array([[j.offset.x, j.offset.y, j.offset.z] for j in m.joints], dtype=np.float64).reshape(n, 3)
        rest_t = np.array(
            [[t.x, t.y, t.z] for t in (j.rest_translation if j.HasField("rest_translation") else j.offset for j in m.joints)],
            dtype=np.float64).reshape(n, 3)
        rest_q = np.array(
            [[j.rest_rotation.x, j.rest_rotation.y, j.rest_rotation.z, j.rest_rotation.w]
             if j.HasField("rest_rotation") else [0.0, 0.0, 0.0, 1.0] for j in m.joints],
            dtype=np.float64).reshape(n, 4)
        channels = []
        for j in m.joints:
            if any(not 0 <= c < 6 for c in j.channels):
                raise GmrError("PROTOCOL", f"joint '{j.name}' has an unknown channel type")
            channels.append([_CHANNELS[c] for c in j.channels])
        return Skeleton(names, parents, np.array([j.soft_parent for j in m.joints], dtype=np.int32), offsets,
                        channels, rest_t, rest_q)


@dataclasses.dataclass
class MotionInfo:
    name: str
    joint_count: int
    frame_count: int
    frame_time: float
    source: str
    metres_per_unit: float  # 0: unknown


@dataclasses.dataclass
class Publication:
    """A live source this client publishes (docs/live.md)."""
    id: int
    motion: str     # its name in the server's list: views and subscriptions use it
    recording: str  # with record=True: the file the server writes when the publication ends
    channel_count: int


@dataclasses.dataclass
class View:
    id: int
    motion: str
    skeleton_version: int
    skeleton: Skeleton
    relative_to: str  # empty: world coordinates
    frame_count: int
    frame_time: float
    removed: List[str]
    join_offset_spread: float


@dataclasses.dataclass
class QueryResult:
    skeleton_version: int
    begin: int
    end: int
    joints: np.ndarray                         # (J,) joint indices of the values
    positions: np.ndarray                      # (frames, J, 3)
    orientations: Optional[np.ndarray]         # (frames, J, 4) x y z w, when asked
    local_rotations: Optional[np.ndarray]      # (frames, J, 4), when asked
    local_translations: Optional[np.ndarray]   # (frames, J, 3), when asked


@dataclasses.dataclass
class Frame:
    subscription_id: int
    view_id: int
    stream_id: int
    skeleton_version: int
    frame_index: int
    motion_time: float
    sequence: int
    server_send_time_ns: int   # when the server encoded it (system_clock ns)
    server_write_time_ns: int  # when the server handed it to the kernel (0: not stamped)
    receive_time_ns: int
    udp: bool
    positions: np.ndarray                     # (J, 3)
    orientations: Optional[np.ndarray]        # (J, 4) x y z w
    local_rotations: Optional[np.ndarray]     # (J, 4)
    local_translations: Optional[np.ndarray]  # (J, 3)


def _values(flat, width: int, count: Optional[int], what: str) -> Optional[np.ndarray]:
    """A repeated field as (count, width) values; None when empty."""
    if len(flat) == 0:
        return None
    a = np.asarray(flat, dtype=np.float64)
    if a.size % width != 0 or (count is not None and a.size != count * width):
        expected = f"{count * width}" if count is not None else f"a multiple of {width}"
        raise GmrError("PROTOCOL", f"{a.size} {what} values (expected {expected})")
    return a.reshape(-1, width)


def _decode_frame(f, udp: bool) -> Frame:
    f64 = len(f.positions_f64) > 0
    positions = _values(f.positions_f64 if f64 else f.positions, 3, None, "position")
    if positions is None:
        positions = np.zeros((0, 3))
    n = positions.shape[0]
    orientations = _values(f.orientations_f64 if f64 else f.orientations, 4, n, "orientation")
    local_r = _values(f.local_rotations_f64 if f64 else f.local_rotations, 4, n, "local rotation")
    local_t = _values(f.local_translations_f64 if f64 else f.local_translations, 3, n, "local translation")
    if (local_r is None) != (local_t is None):
        raise GmrError("PROTOCOL", "local rotations without local translations, or the other way round")
    return Frame(f.subscription_id, f.view_id, f.stream_id, f.skeleton_version, f.frame_index, f.motion_time,
                 f.sequence, f.server_send_time_ns, f.server_write_time_ns, time.time_ns(), udp, positions,
                 orientations, local_r, local_t)
