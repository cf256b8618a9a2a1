"""A client for gmr-server (docs/protocol.md), in plain Python with numpy.

One Client is one TCP connection (and, for UDP subscriptions, one UDP
socket). It is synchronous and single-threaded: a request waits for its
reply, and frames are read whenever the client reads (a request, `poll()`,
or iterating a subscription). Nothing runs in the background, so the caller
decides when the socket is read: a game loop or Blender's timer calls
`poll()` (or `Subscription.latest()`) and never blocks.

    with Client(port=7400) as c:
        view = c.create_view("walk")
        c.shift_root(view.id, "head")
        q = c.query(view.id, 0, 10)                 # q.positions: (10, joints, 3)
        sub = c.subscribe(view.id, max_frames=100, conventions="blender")
        for frame in sub:                           # frame.positions: (joints, 3)
            ...

A client with the publish role is also a live source (docs/live.md):

        pub = c.publish("lab/tracker", Skeleton.points(names), 1 / 120)
        c.publish_frame(pub, positions)             # (joints, 3), one call per frame

The package is split as the C++ client is: this module is the connection
and its requests (reads, replies, heartbeats, UDP receive); subscriptions.py
the subscriptions' bookkeeping and what is delivered to them; values.py the
values handed out; _wire.py framing and UDP datagrams.
"""

import collections
import select
import socket
import time
from typing import Dict, List, Optional, Sequence, Union

import numpy as np

from . import _wire
from . import stream_pb2 as pb
from .subscriptions import Subscription, Subscriptions
from .values import (ConventionsLike, GmrError, MotionInfo, Publication, QueryResult, Skeleton, View, _decode_frame,
                     _set_conventions, _values)

PROTOCOL_VERSION = 1
DEFAULT_PORT = 7400
# The largest message this client takes from a server, as the C++ client's
# ClientOptions::max_message_bytes; a server's HelloReply never raises it.
_DEFAULT_MAX_MESSAGE_BYTES = 16 << 20


def _code_name(code: int) -> str:
    """An error code's name without its prefix; one this client does not know
    (a newer or a hostile server) as UNKNOWN_<number>, never a ValueError."""
    try:
        return pb.ErrorCode.Name(code).replace("ERROR_CODE_", "")
    except ValueError:
        return f"UNKNOWN_{code}"


class Client:
    def __init__(self, host: str = "127.0.0.1", port: int = DEFAULT_PORT, *, name: str = "gmr-python",
                 token: str = "", timeout: float = 5.0, max_message_bytes: int = _DEFAULT_MAX_MESSAGE_BYTES):
        self.timeout = timeout
        self._next_request = 1
        self._replies = {}
        self._subs = Subscriptions()
        self._buffer = bytearray()
        self._udp = None
        self._udp_registered = False
        self._reassembler = _wire.Reassembler()
        self._max_message = max_message_bytes
        self.frames_malformed = 0
        self._awaiting = set()  # request ids a call waits for; other replies are errors to keep
        self._errors = collections.deque(maxlen=64)  # refusals of requests that get no reply
        self._publications = {}  # id -> channel count
        try:
            self._sock = socket.create_connection((host, port), timeout=timeout)
        except OSError as e:
            raise GmrError("CONNECTION", f"cannot connect to {host}:{port}: {e.strerror or e}") from None
        self._sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self._host = self._sock.getpeername()[0]
        self._last_send = time.monotonic()
        m = pb.ClientMessage()
        m.hello.protocol_version = PROTOCOL_VERSION
        m.hello.client_name = name
        m.hello.auth_token = token
        sent = time.time_ns()
        self.hello = self._request(m, "hello")
        answered = time.time_ns()
        # The server's clock minus ours, from the round trip (0 if it does not
        # say): frames' ages are measured with it.
        self.clock_offset_ns = self.hello.server_time_ns - (sent + answered) // 2 if self.hello.server_time_ns else 0

    # ------------------------------------------------------------ lifetime

    def close(self) -> None:
        for s in (self._sock, self._udp):
            if s is not None:
                s.close()
        self._sock = None
        self._udp = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    # ------------------------------------------------------------ requests

    def list_motions(self) -> List[MotionInfo]:
        r = self._ask("list_motions", "motions")
        return [MotionInfo(x.name, x.joint_count, x.frame_count, x.frame_time, x.source, x.metres_per_unit)
                for x in r.motions]

    def skeleton(self, motion: str, conventions: ConventionsLike = None) -> Skeleton:
        """The motion's skeleton, with its rest pose in `conventions`."""
        m = pb.ClientMessage()
        m.get_skeleton.motion = motion
        _set_conventions(conventions, m.get_skeleton.conventions)
        return Skeleton.from_proto(self._request(m, "skeleton").skeleton)

    def create_view(self, motion: str) -> View:
        return self._view(self._ask("create_view", "view", motion=motion))

    def close_view(self, view: int) -> None:
        self._ask("close_view", "ack", view_id=view)

    def shift_root(self, view: int, joint: str) -> View:
        return self._view(self._ask("shift_root", "view", view_id=view, joint=joint))

    def split(self, view: int, joint: str) -> View:
        return self._view(self._ask("split", "view", view_id=view, joint=joint))

    def join(self, view: int, root: str) -> View:
        return self._view(self._ask("join", "view", view_id=view, root=root))

    def set_roots(self, view: int, roots: Sequence[str]) -> View:
        m = pb.ClientMessage()
        m.set_roots.view_id = view
        m.set_roots.roots.extend(roots)
        return self._view(self._request(m, "view"))

    def strip_dummies(self, view: int) -> View:
        return self._view(self._ask("strip_dummies", "view", view_id=view))

    def set_coordinates(self, view: int, relative_to: str = "") -> View:
        """World coordinates (""), or the motion seen from joint `relative_to`."""
        return self._view(self._ask("set_coordinates", "view", view_id=view, relative_to=relative_to))

    def retarget(self, view: int, rig: Skeleton, reference: Sequence[float] = (),
                 rig_map: Optional[Dict[str, str]] = None, source_map: Optional[Dict[str, str]] = None,
                 metres_per_unit: float = 0.0) -> View:
        """The view's motion put on another humanoid rig (docs/retarget.md):
        `rig` its skeleton in the motion's axes (a library motion's,
        `skeleton("rigs/mine")`, or one built by hand), `reference` the rig's
        channel values in a pose it stands in when its rest pose does not, the
        maps role -> joint name (none: the built-in namings), the rig's unit
        in metres (0: the motion's). Subscriptions then get the rig's joints,
        in the rig's unit."""
        m = pb.ClientMessage()
        r = m.retarget
        r.view_id = view
        rig.to_proto(r.target)
        r.target.metres_per_unit = float(metres_per_unit)
        r.reference.extend(float(v) for v in reference)
        for role, joint in (rig_map or {}).items():
            r.target_map[role] = joint
        for role, joint in (source_map or {}).items():
            r.source_map[role] = joint
        return self._view(self._request(m, "view"))

    def query(self, view: int, begin: int, end: int = 0, *, orientations: bool = False,
              local_transforms: bool = False, joints: Sequence[str] = (),
              conventions: ConventionsLike = None) -> QueryResult:
        """Frames [begin, end) (end 0: begin + 1) of a view, in float64."""
        m = pb.ClientMessage()
        q = m.query_frames
        q.view_id = view
        q.begin = begin
        q.end = end
        q.orientations = orientations
        q.local_transforms = local_transforms
        q.joints.extend(joints)
        _set_conventions(conventions, q.conventions)
        b = self._request(m, "frames")
        frames = b.end - b.begin if b.end >= b.begin else -1
        count = frames * len(b.joints)
        if frames < 0:
            raise GmrError("PROTOCOL", f"a frame block for frames [{b.begin}, {b.end})")

        def shaped(flat, width, what):
            v = _values(flat, width, count, what)
            return None if v is None else v.reshape(frames, len(b.joints), width)

        positions = shaped(b.positions, 3, "position")
        if positions is None:
            positions = np.zeros((frames, len(b.joints), 3))
        local_r = shaped(b.local_rotations, 4, "local rotation")
        local_t = shaped(b.local_translations, 3, "local translation")
        return QueryResult(b.skeleton_version, b.begin, b.end, np.array(b.joints, dtype=np.int32), positions,
                           shaped(b.orientations, 4, "orientation"), local_r, local_t)

    def subscribe(self, view: int, *, start_frame: int = 0, end_frame: int = 0, loop: bool = False,
                  speed: float = 1.0, rate_hz: float = 0.0, skip_repeats: bool = False, orientations: bool = False,
                  local_transforms: bool = False, joints: Sequence[str] = (), udp: bool = False,
                  float64: bool = False, shared: bool = False, max_frames: int = 0,
                  conventions: ConventionsLike = None, max_staleness_ms: int = 0,
                  paused: bool = False) -> Subscription:
        """Starts streaming frames of a view (docs/protocol.md, "Streams").

        By default (max_staleness_ms=0) every frame that reaches this client
        is handed out, however late the script reads it: a 30 Hz
        subscription read after 0.5 s yields the 15 frames sent meanwhile.
        A live consumer that wants only fresh frames (a game loop, the
        Blender add-on) gives a bound, e.g. 100: frames older than it are
        never handed out (the server drops those that waited in its queue,
        this client those that arrive older) and are counted in
        Subscription.frames_stale.

        paused=True starts held at start_frame: that one frame comes, then
        nothing until resume()."""
        if udp:
            self.register_udp()
        m = pb.ClientMessage()
        s = m.subscribe
        s.view_id = view
        s.start_frame = start_frame
        s.end_frame = end_frame
        s.loop = loop
        s.speed = speed
        s.rate_hz = rate_hz
        s.skip_repeats = skip_repeats
        s.orientations = orientations
        s.local_transforms = local_transforms
        s.joints.extend(joints)
        s.transport = pb.TRANSPORT_UDP if udp else pb.TRANSPORT_TCP
        s.precision = pb.PRECISION_FLOAT64 if float64 else pb.PRECISION_FLOAT32
        s.shared = shared
        s.max_frames = max_frames
        s.paused = paused
        s.max_staleness_ms = max_staleness_ms if max_staleness_ms > 0 else 0xFFFFFFFF  # 0 on the wire: 100 ms
        _set_conventions(conventions, s.conventions)
        # Frames and pushes can come before the reply is handled (in the same
        # read, or by UDP): they wait until the subscription exists.
        self._subs.subscribing = True
        try:
            reply = self._request(m, "subscribed")
        finally:
            self._subs.subscribing = False
        sub = Subscription(self, reply)
        sub.max_age_ns = max_staleness_ms * 1_000_000 if max_staleness_ms > 0 else 0
        for msg in self._subs.add(sub):
            self._on_message(msg, udp=False)
        return sub

    def unsubscribe(self, subscription: int) -> None:
        self._ask("unsubscribe", "ack", subscription_id=subscription)
        self._subs.remove(subscription)

    def pause(self, subscription: int) -> None:
        self._ask("pause", "ack", subscription_id=subscription)

    def resume(self, subscription: int) -> None:
        self._ask("resume", "ack", subscription_id=subscription)

    def seek(self, subscription: int, frame: int) -> None:
        self._ask("seek", "ack", subscription_id=subscription, frame=frame)

    def stats(self):
        return self._ask("get_stats", "stats")

    # ------------------------------------------------------------ live sources

    def publish(self, name: str, skeleton: Skeleton, frame_time: float, *, metres_per_unit: float = 0.0,
                record: bool = False) -> Publication:
        """Makes this client a live source (docs/live.md): `name` joins the
        server's list, and views of it stream each frame given to
        publish_frame. Needs the publish role (an auth file's `publish TOKEN`,
        or a server started with --anonymous publish). With `record`, the
        server writes what it accepted as .gmrb when the publication ends."""
        m = pb.ClientMessage()
        p = m.publish
        p.name = name
        skeleton.to_proto(p.skeleton)
        p.frame_time = frame_time
        p.metres_per_unit = metres_per_unit
        p.record = record
        r = self._request(m, "published")
        self._publications[r.publication_id] = skeleton.channel_count
        return Publication(r.publication_id, r.motion, r.recording, skeleton.channel_count)

    def publish_frame(self, publication: Union[int, Publication], values) -> None:
        """Sends one frame: the skeleton's channel values in its order (joint
        by joint, each joint's channels as published; degrees for rotations),
        as a flat sequence or an array of any shape. No reply: a frame the
        server refuses is kept for take_errors(). Reads what has arrived
        without waiting, so a publisher that only publishes stays current."""
        pid = publication.id if isinstance(publication, Publication) else int(publication)
        flat = np.asarray(values, dtype=np.float64).reshape(-1)
        expected = self._publications.get(pid)
        if expected is not None and flat.size != expected:
            raise ValueError(f"publication {pid} takes {expected} channel values per frame, not {flat.size}")
        m = pb.ClientMessage()
        m.request_id = self._next_request  # a refusal names it
        self._next_request += 1
        m.publish_frame.publication_id = pid
        m.publish_frame.values.extend(flat.tolist())
        self._send(m)
        self._pump(0.0)

    def unpublish(self, publication: Union[int, Publication]) -> None:
        """Ends a publication: its subscribers' subscriptions end."""
        pid = publication.id if isinstance(publication, Publication) else int(publication)
        self._ask("unpublish", "ack", publication_id=pid)
        self._publications.pop(pid, None)

    def take_errors(self) -> List[str]:
        """Refusals of requests that get no reply (publish_frame), oldest
        first, as "CODE: message"; at most the last 64 are kept."""
        out = list(self._errors)
        self._errors.clear()
        return out

    def register_udp(self) -> None:
        """Registers this connection's UDP endpoint (register, challenge, confirm; docs/protocol.md, "UDP")."""
        if self._udp_registered:
            return
        if not self.hello.udp_port:
            raise GmrError("FAILED_PRECONDITION", "the server offers no UDP")
        if self._udp is None:
            family = socket.AF_INET6 if ":" in self._host else socket.AF_INET
            self._udp = socket.socket(family, socket.SOCK_DGRAM)
            self._udp.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4 << 20)
            self._udp.bind(("::" if family == socket.AF_INET6 else "0.0.0.0", 0))
        server = (self._host, self.hello.udp_port)
        token = bytes(self.hello.udp_token)
        deadline = time.monotonic() + self.timeout
        next_send = 0.0
        while not self._udp_registered:
            now = time.monotonic()
            if now >= deadline:
                raise GmrError("CONNECTION", "the server did not confirm the UDP registration in time")
            if now >= next_send:  # datagrams can be lost: resend until confirmed
                self._udp.sendto(_wire.register_datagram(token), server)
                next_send = now + 0.05
            self._pump(min(0.05, deadline - now), udp_handshake=(token, server))

    def poll(self, timeout: float = 0.0) -> None:
        """Reads whatever has arrived (frames go to their subscriptions), waiting
        at most `timeout` seconds for the first message. Sends a heartbeat when
        this client has sent nothing for a third of the server's idle timeout
        (without one, its heartbeat interval)."""
        self._pump(timeout)
        while self._pump(0.0):
            pass

    # ------------------------------------------------------------ internals

    def _send(self, m) -> None:
        if self._sock is None:
            raise GmrError("CONNECTION", "the client is closed")
        data = m.SerializeToString()
        try:
            self._sock.sendall(_wire.frame_message(data))
        except OSError as e:
            self.close()
            raise GmrError("CONNECTION", f"the connection broke: {e}") from None
        self._last_send = time.monotonic()

    def _request(self, m, expect: str):
        m.request_id = self._next_request
        self._next_request += 1
        self._awaiting.add(m.request_id)
        try:
            self._send(m)
            deadline = time.monotonic() + self.timeout
            while m.request_id not in self._replies:
                left = deadline - time.monotonic()
                if left <= 0:
                    raise GmrError("CONNECTION", f"no reply to request {m.request_id} within {self.timeout} s")
                self._pump(left)
        finally:
            self._awaiting.discard(m.request_id)
        r = self._replies.pop(m.request_id)
        which = r.WhichOneof("body")
        if which == "error":
            raise GmrError(_code_name(r.error.code), r.error.message)
        if which != expect:
            raise GmrError("PROTOCOL", f"expected a '{expect}' reply, got '{which}'")
        return getattr(r, which)

    def _ask(self, body: str, expect: str, **fields):
        """Sends a request whose body has only scalar fields and returns the reply's `expect` part."""
        m = pb.ClientMessage()
        part = getattr(m, body)
        part.SetInParent()
        for name, value in fields.items():
            setattr(part, name, value)
        return self._request(m, expect)

    @staticmethod
    def _view(v) -> View:
        return View(v.view_id, v.motion, v.skeleton_version, Skeleton.from_proto(v.skeleton), v.relative_to,
                    v.frame_count, v.frame_time, list(v.removed), v.join_offset_spread)

    def _pump(self, timeout: float, udp_handshake=None) -> bool:
        """Waits up to `timeout` for data and handles one batch of it, then ends
        the subscriptions whose held end notice's grace is over. True if
        anything was read."""
        got = self._read_some(timeout, udp_handshake)
        self._subs.expire_endings()
        return got

    def _read_some(self, timeout: float, udp_handshake) -> bool:
        if self._sock is None:
            raise GmrError("CONNECTION", "the client is closed")
        interval = 0.0
        if hasattr(self, "hello"):
            # A heartbeat every third of the server's idle timeout (without
            # one, its heartbeat interval), 10 ms at the least, as the C++
            # client does: the idle rule is what heartbeats are for, and each
            # is a wake-up and a read on the server.
            ms = self.hello.idle_timeout_ms / 3 or self.hello.heartbeat_interval_ms
            interval = max(10, ms) / 1000.0 if ms else 0.0
        if interval and time.monotonic() - self._last_send > interval:
            h = pb.ClientMessage()
            h.heartbeat.client_time_ns = time.time_ns()
            self._send(h)
        if self._take_buffered():
            return True
        sockets = [self._sock] + ([self._udp] if self._udp is not None else [])
        ready, _, _ = select.select(sockets, [], [], max(0.0, timeout))
        got = False
        if self._udp is not None and self._udp in ready:
            got = True
            for _ in range(256):  # what is waiting, without starving TCP
                try:
                    datagram, source = self._udp.recvfrom(65536)
                except BlockingIOError:
                    break
                self._on_datagram(datagram, udp_handshake)
                if not select.select([self._udp], [], [], 0)[0]:
                    break
        if self._sock in ready:
            try:
                data = self._sock.recv(1 << 20)
            except OSError as e:
                self.close()
                raise GmrError("CONNECTION", f"the connection broke: {e}") from None
            if not data:
                self.close()
                raise GmrError("CONNECTION", "the server closed the connection")
            self._buffer += data
            got = True
            self._take_buffered()
        return got

    def _take_buffered(self) -> bool:
        took = False
        while len(self._buffer) >= 4:
            (length,) = _wire.LENGTH_PREFIX.unpack_from(self._buffer, 0)
            if length > self._max_message:
                self.close()
                raise GmrError("PROTOCOL", f"a message of {length} bytes, above the limit of {self._max_message}")
            if len(self._buffer) < 4 + length:
                break
            body = bytes(self._buffer[4:4 + length])
            del self._buffer[:4 + length]
            msg = pb.ServerMessage()
            try:
                msg.ParseFromString(body)
            except Exception as e:  # the library's DecodeError
                self.close()
                raise GmrError("PROTOCOL", f"a malformed message: {e}") from None
            self._on_message(msg, udp=False)
            took = True
        return took

    def _on_datagram(self, datagram: bytes, udp_handshake) -> None:
        if udp_handshake is not None:
            cookie = _wire.challenge_cookie(datagram)
            if cookie is not None:
                token, server = udp_handshake
                self._udp.sendto(_wire.confirm_datagram(token, cookie), server)
                return
        message = self._reassembler.feed(datagram)
        if message is None:
            return
        msg = pb.ServerMessage()
        try:
            msg.ParseFromString(message)
        except Exception:
            self.frames_malformed += 1
            return
        if msg.HasField("frame"):
            self._on_message(msg, udp=True)

    def _on_message(self, msg, udp: bool) -> None:
        which = msg.WhichOneof("body")
        if which == "frame":
            try:
                frame = _decode_frame(msg.frame, udp)
            except GmrError:
                self.frames_malformed += 1
                return
            self._subs.on_frame(frame, self.clock_offset_ns)
        elif which in ("subscription_ended", "skeleton_changed") and self._subs.hold(msg, which):
            pass  # handled once its subscription is registered
        elif which == "subscription_ended":
            self._subs.on_ended(msg.subscription_ended)
        elif which == "skeleton_changed":
            self._subs.on_skeleton_changed(msg.skeleton_changed)
        elif which == "udp_registered":
            self._udp_registered = True
        elif which == "heartbeat":
            pass
        elif msg.request_id in self._awaiting:
            self._replies[msg.request_id] = msg
        elif msg.request_id and which == "error":  # a request that gets no reply was refused
            self._errors.append(f"{_code_name(msg.error.code)}: {msg.error.message}")
        elif msg.request_id:
            pass  # a reply nobody waits for any more (its request timed out)
        elif which == "error":  # an error about no request: the server is closing the connection
            raise GmrError(_code_name(msg.error.code), msg.error.message)
