"""The byte-level parts of gmr's protocol (docs/protocol.md): TCP framing and
UDP datagrams (registration and fragments).

TCP: every message is a 4-byte big-endian length and that many bytes of a
serialized ClientMessage or ServerMessage. UDP: every datagram starts with
"GMRU", the datagram version, its kind and two zero bytes.
"""

import collections
import struct

LENGTH_PREFIX = struct.Struct(">I")
UDP_MAGIC = b"GMRU"
UDP_VERSION = 2
KIND_REGISTER, KIND_FRAGMENT, KIND_CHALLENGE, KIND_CONFIRM = 1, 2, 3, 4
UDP_HEADER_BYTES = 8
TOKEN_BYTES = 16
FRAGMENT_HEADER = struct.Struct(">IHHI")  # message id, index, count, total size
FRAGMENT_HEADER_BYTES = UDP_HEADER_BYTES + FRAGMENT_HEADER.size
MAX_DATAGRAM_BYTES = 1200
MAX_FRAGMENT_PAYLOAD = MAX_DATAGRAM_BYTES - FRAGMENT_HEADER_BYTES
MAX_UDP_MESSAGE_BYTES = 1 << 20


def frame_message(serialized: bytes) -> bytes:
    """A serialized message with its length prefix."""
    return LENGTH_PREFIX.pack(len(serialized)) + serialized


def _header(kind: int) -> bytes:
    return UDP_MAGIC + bytes([UDP_VERSION, kind, 0, 0])


def _kind_of(datagram: bytes):
    if len(datagram) < UDP_HEADER_BYTES or datagram[:4] != UDP_MAGIC or datagram[4] != UDP_VERSION:
        return None
    return datagram[5]


def register_datagram(token: bytes) -> bytes:
    return _header(KIND_REGISTER) + token


def confirm_datagram(token: bytes, cookie: bytes) -> bytes:
    return _header(KIND_CONFIRM) + token + cookie


def challenge_cookie(datagram: bytes):
    """The cookie of a challenge datagram, or None for anything else."""
    if len(datagram) != UDP_HEADER_BYTES + TOKEN_BYTES or _kind_of(datagram) != KIND_CHALLENGE:
        return None
    return datagram[UDP_HEADER_BYTES:]


class Reassembler:
    """Rebuilds messages from fragments that arrive late, twice, out of order
    or not at all. At most MAX_PARTIAL messages are in progress; one more
    drops the oldest incomplete one whole (memory stays bounded)."""

    MAX_PARTIAL = 8

    def __init__(self):
        self._partial = {}  # message id -> [count, total, {index: bytes}]
        self._recent_done = collections.deque(maxlen=4 * self.MAX_PARTIAL)  # a duplicate of one is ignored
        self.dropped = 0    # messages dropped with a fragment missing
        self.malformed = 0  # datagrams that were not well-formed fragments

    def feed(self, datagram: bytes):
        """Returns the whole message when `datagram` completes one, else None."""
        if _kind_of(datagram) != KIND_FRAGMENT or len(datagram) < FRAGMENT_HEADER_BYTES:
            self.malformed += 1
            return None
        message_id, index, count, total = FRAGMENT_HEADER.unpack_from(datagram, UDP_HEADER_BYTES)
        payload = datagram[FRAGMENT_HEADER_BYTES:]
        expected_count = max(1, -(-total // MAX_FRAGMENT_PAYLOAD))
        expected_size = MAX_FRAGMENT_PAYLOAD if index + 1 < count else total - (count - 1) * MAX_FRAGMENT_PAYLOAD
        if total > MAX_UDP_MESSAGE_BYTES or count != expected_count or index >= count or len(payload) != expected_size:
            self.malformed += 1
            return None
        if message_id in self._recent_done:
            return None
        if count == 1:
            self._recent_done.append(message_id)
            return bytes(payload)
        entry = self._partial.get(message_id)
        if entry is None:
            if len(self._partial) >= self.MAX_PARTIAL:
                oldest = next(iter(self._partial))
                del self._partial[oldest]
                self.dropped += 1
            entry = self._partial[message_id] = [count, total, {}]
        if entry[0] != count or entry[1] != total:
            self.malformed += 1
            return None
        entry[2][index] = bytes(payload)
        if len(entry[2]) < count:
            return None
        del self._partial[message_id]
        self._recent_done.append(message_id)
        return b"".join(entry[2][i] for i in range(count))
