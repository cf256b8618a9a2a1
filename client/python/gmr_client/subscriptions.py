"""A client's subscriptions and what arrives for them: frames (dropped when
of another skeleton version or too old, queued otherwise), the end notice
(held while frames it counts are still on their way), new skeletons, and
what comes before the Subscribed reply that registers a subscription.
Mirrors the C++ client's delivery.cpp."""

import collections
import time
from typing import List, Optional

import numpy as np

from .values import Frame, GmrError, Skeleton

_MAX_QUEUED_FRAMES = 1024  # per subscription; older frames give way (counted)
_END_GRACE_S = 0.1  # how long an end notice waits for the frames it counts (UDP)


def _frames_to_come(end: dict) -> int:
    """How many frames an ended subscription's client gets: those the server
    counted against it, less those it dropped or skipped."""
    return max(0, end["frames_sent"] - end["frames_dropped"] - end["frames_skipped"])


def _check_joints(joints: np.ndarray, skeleton: Optional[Skeleton]) -> None:
    """A server's joint indices must name joints of its skeleton."""
    if skeleton is not None and len(joints) and (joints.min() < 0 or joints.max() >= len(skeleton.names)):
        bad = int(joints.max() if joints.max() >= len(skeleton.names) else joints.min())
        raise GmrError("PROTOCOL", f"joint index {bad} of a skeleton of {len(skeleton.names)} joints")


def _values_per_frame(joints: np.ndarray, skeleton: Optional[Skeleton]) -> int:
    """The positions each frame carries: one per subscribed joint (0: unknown)."""
    if len(joints):
        return len(joints)
    return len(skeleton.names) if skeleton is not None else 0


class Subscription:
    """A running subscription. Iterate it for its frames (blocking until the
    next one, ending when the server ends it), or call `latest()` from a loop
    that must not block. `skeleton`, `joints` and `skeleton_version` follow
    the server's SkeletonChanged pushes, and every frame handed out is of
    that version: a frame of another one (a UDP frame of the new version
    overtaking its SkeletonChanged, an old one still queued behind it, or
    waiting here unread when the skeleton changed) is dropped and counted in
    `frames_other_skeleton`."""

    def __init__(self, client: "Client", reply):
        self._client = client
        self.id = reply.subscription_id
        self.view_id = reply.view_id
        self.skeleton_version = reply.skeleton_version
        skeleton = Skeleton.from_proto(reply.skeleton) if reply.HasField("skeleton") else None
        joints = np.array(reply.joints, dtype=np.int64)
        _check_joints(joints, skeleton)
        self.joints = joints.astype(np.int32)
        self.rate_hz = reply.rate_hz
        self.stream_id = reply.stream_id
        self.joined_running = reply.joined_running
        self.skeleton = skeleton
        self._values = _values_per_frame(self.joints, self.skeleton)
        self.relative_to = reply.relative_to
        # The unit of the frames' positions in metres (the conventions' when
        # the motion's unit is known); 0.0: unknown, the motion's own units.
        self.metres_per_unit = reply.skeleton.metres_per_unit if reply.HasField("skeleton") else 0.0
        self.ended = None  # dict(reason, frames_sent, frames_dropped, frames_skipped) once ended
        self.skeleton_changes = 0
        self.frames_overflowed = 0  # frames this client queued but nobody read in time
        self.frames_stale = 0       # frames that arrived older than max_staleness (dropped)
        self.max_age_ns = 0         # 0: no staleness bound
        self.frames_other_skeleton = 0  # frames of another skeleton version than `skeleton_version` (dropped)
        self.frames_malformed = 0  # frames whose values do not fit the subscribed joints (dropped)
        self.arrived = 0  # frames that came for it, whatever became of them
        # The end notice, held while frames it counts are still on their way
        # (a UDP frame can be overtaken by the TCP notice), until they come or
        # the grace period is over: `ended` is set after the last frame.
        self._ending = None
        self._ending_deadline = 0.0
        self._frames = collections.deque()

    def _push(self, frame: Frame) -> None:
        if frame.skeleton_version != self.skeleton_version:
            self.frames_other_skeleton += 1
            return
        if self._values and len(frame.positions) != self._values:
            self.frames_malformed += 1
            return
        if len(self._frames) >= _MAX_QUEUED_FRAMES:
            self._frames.popleft()
            self.frames_overflowed += 1
        self._frames.append(frame)

    def _skeleton_changed(self, c) -> None:
        skeleton = Skeleton.from_proto(c.skeleton)
        joints = np.array(c.joints, dtype=np.int64)
        _check_joints(joints, skeleton)
        self.skeleton_version = c.skeleton_version
        self.skeleton = skeleton
        self.joints = joints.astype(np.int32)
        self._values = _values_per_frame(self.joints, self.skeleton)
        self.relative_to = c.relative_to
        self.skeleton_changes += 1
        kept = [f for f in self._frames if f.skeleton_version == self.skeleton_version]
        self.frames_other_skeleton += len(self._frames) - len(kept)
        self._frames = collections.deque(kept)

    def __iter__(self):
        while True:
            if self._frames:
                yield self._frames.popleft()
            elif self.ended is not None:
                return
            else:
                wait = self._client.timeout
                if self._ending is not None:
                    wait = min(wait, max(0.0, self._ending_deadline - time.monotonic()))
                self._client._pump(wait)

    def frames(self) -> List[Frame]:
        """Every frame that arrived and was not read yet (reads the sockets first, without blocking)."""
        self._client.poll(0.0)
        out = list(self._frames)
        self._frames.clear()
        return out

    def latest(self) -> Optional[Frame]:
        """The newest frame that arrived, dropping older unread ones; None if none (never blocks)."""
        frames = self.frames()
        return frames[-1] if frames else None

    def unsubscribe(self) -> None:
        self._client.unsubscribe(self.id)


class Subscriptions:
    """The subscriptions of one client, by id, and what arrived for a
    subscription before its Subscribed reply was handled (in the same read,
    or over UDP): its frames, and pushes such as a short one's end notice."""

    def __init__(self):
        self._subs = {}
        self._early = collections.defaultdict(list)  # frames that came before their Subscribed reply
        self._early_pushes = []
        self.subscribing = False  # a Subscribe is waiting for its reply

    def get(self, subscription_id: int) -> Optional[Subscription]:
        return self._subs.get(subscription_id)

    def add(self, sub: Subscription) -> list:
        """Registers `sub` (its reply came) and gives it the frames that came
        early; returns the pushes held meanwhile, to be handled again."""
        self._subs[sub.id] = sub
        for frame in self._early.pop(sub.id, []):
            sub.arrived += 1
            sub._push(frame)
        self._early.clear()
        pushes, self._early_pushes = self._early_pushes, []
        return pushes

    def remove(self, subscription_id: int) -> None:
        """The subscription was unsubscribed: it ends now (with its held notice, if any)."""
        sub = self._subs.pop(subscription_id, None)
        if sub is not None and sub._ending is not None:
            sub.ended, sub._ending = sub._ending, None
        if sub is not None and sub.ended is None:
            sub.ended = {"reason": "unsubscribed", "frames_sent": 0, "frames_dropped": 0, "frames_skipped": 0,
                         "frames_stale": 0}

    def on_frame(self, frame: Frame, clock_offset_ns: int) -> None:
        sub = self._subs.get(frame.subscription_id)
        if sub is not None:
            sub.arrived += 1
            if sub.max_age_ns and frame.receive_time_ns + clock_offset_ns - frame.server_send_time_ns > sub.max_age_ns:
                sub.frames_stale += 1  # waited in the kernel's buffers while we were not reading
            else:
                sub._push(frame)
            if sub._ending is not None and sub.arrived >= _frames_to_come(sub._ending):
                self._end(sub)
        elif self.subscribing and len(self._early[frame.subscription_id]) < _MAX_QUEUED_FRAMES:
            self._early[frame.subscription_id].append(frame)

    def hold(self, msg, which: str) -> bool:
        """Keeps a push about a subscription not registered yet while a
        Subscribe waits (True: held, to be handled once it is)."""
        if not self.subscribing or getattr(msg, which).subscription_id in self._subs:
            return False
        if len(self._early_pushes) < _MAX_QUEUED_FRAMES:
            self._early_pushes.append(msg)
        return True

    def on_ended(self, e) -> None:
        sub = self._subs.get(e.subscription_id)
        if sub is not None and sub._ending is None:
            sub._ending = {"reason": e.reason, "frames_sent": e.frames_sent, "frames_dropped": e.frames_dropped,
                           "frames_skipped": e.frames_skipped, "frames_stale": e.frames_stale}
            sub._ending_deadline = time.monotonic() + _END_GRACE_S
            if sub.arrived >= _frames_to_come(sub._ending):
                self._end(sub)

    def on_skeleton_changed(self, c) -> None:
        sub = self._subs.get(c.subscription_id)
        if sub is not None:
            try:
                sub._skeleton_changed(c)
            except GmrError:
                # Not taken: the frames of its version are dropped as another skeleton's.
                sub.frames_malformed += 1

    def expire_endings(self) -> None:
        """Ends the subscriptions whose held end notice's grace is over."""
        now = time.monotonic()
        for sub in [s for s in self._subs.values() if s._ending is not None and now >= s._ending_deadline]:
            self._end(sub)

    def _end(self, sub: Subscription) -> None:
        """Gives a held end notice to its subscription (`ended`), which leaves."""
        sub.ended, sub._ending = sub._ending, None
        if self._subs.get(sub.id) is sub:
            del self._subs[sub.id]
