"""The two rosserial v2 checksums (fact sheet sec. 1.2).

Both are "255 minus the byte sum mod 256", so a receiver checks that the covered bytes plus the
checksum byte sum to 255 mod 256.
"""

from __future__ import annotations

from zlib import adler32

_EXACT_CHUNK = 256  # 256 * 255 < 65521: adler32's low word is the plain byte sum


def length_checksum(length: int) -> int:
    """Checksum byte after the uint16 payload length: ``255 - ((lo + hi) % 256)``."""
    return 255 - (((length & 0xFF) + ((length >> 8) & 0xFF)) % 256)


def message_checksum(topic_id: int, payload: bytes) -> int:
    """Checksum byte after the payload: ``255 - ((topic_lo + topic_hi + sum(payload)) % 256)``."""
    return 255 - (((topic_id & 0xFF) + ((topic_id >> 8) & 0xFF) + sum(payload)) % 256)


def length_ok(len_lo: int, len_hi: int, chk: int) -> bool:
    """Receiver test of the header: ``(len_lo + len_hi + chk) % 256 == 255``."""
    return (len_lo + len_hi + chk) % 256 == 255


def message_ok(topic_lo: int, topic_hi: int, payload: bytes, chk: int) -> bool:
    """Receiver test of the body: ``(topic_lo + topic_hi + sum(payload) + chk) % 256 == 255``."""
    return (topic_lo + topic_hi + sum(payload) + chk) % 256 == 255


def byte_sum(data: bytes) -> int:
    """``sum(data)`` computed in C: the low word of Adler-32 started from 0 is the byte sum
    modulo 65521, which is the exact sum for chunks of at most 256 bytes."""
    n = len(data)
    if n <= _EXACT_CHUNK:
        return adler32(data, 0) & 0xFFFF
    view = memoryview(data)
    total = 0
    for start in range(0, n, _EXACT_CHUNK):
        total += adler32(view[start : start + _EXACT_CHUNK], 0) & 0xFFFF
    return total
