"""Hostile payloads for one channel, made from the valid blocks sent on it (issue 16 item 5).

*Malformed* kinds are payloads :func:`millwatch.ingest.wire.decode_block` must reject with a
:class:`~millwatch.ingest.wire.WireError` of a known kind (:data:`MALFORMED` maps each kind to it)
— except ``nonfinite``: the wire format counts NaN/±inf samples in
:attr:`~millwatch.ingest.wire.Block.n_nonfinite`
instead of rejecting them, so that kind is a copy of an already-sent block (same sequence number
and t0) with its samples replaced by NaN/±inf; a worker must drop it as not new.

*Well-formed* kinds decode cleanly but carry a sequence number that is not new
(:data:`WELL_FORMED`): an older block replayed as-is, an exact duplicate of the last block, and
the last block's sequence number again with a t0 hours in the past or in the year 2100 (a
clock fault). None of them may change what the worker analyses.

*Forged* kinds (:data:`FORGED`, issue 26) decode cleanly with a sequence number the channel has
not seen, and are implausible (README "Admission"): sequence number 2^63, the last one
+100,000 (t0 where the next block belongs), and the *next* sequence number with a t0 in the
year 2100 — sent before the real block of that number, which must still be analysed.

>>> import random
>>> import numpy as np
>>> from millwatch.ingest.wire import Unit, decode_block, encode_block
>>> ch = HostileChannel(random.Random(1))
>>> ch.sent(encode_block(np.zeros(4), 10**18, 1000.0, 7, Unit.RPM))
>>> decode_block(ch.make("duplicate")).seq
7
>>> decode_block(ch.make("clock_future")).t0_ns > 4 * 10**18
True
"""

from __future__ import annotations

import random
import struct
from collections import deque
from collections.abc import Iterator, Sequence

import numpy as np

from millwatch.ingest.wire import (
    HEADER,
    HEADER_SIZE,
    MAGIC,
    BadHeaderValue,
    BadMagic,
    LengthMismatch,
    Truncated,
    UnsupportedVersion,
    WireError,
    decode_block,
    encode_block,
)

__all__ = ["FORGED", "KINDS", "MALFORMED", "WELL_FORMED", "HostileChannel", "kind_cycle"]

#: Malformed kind → the :class:`WireError` decoding it raises (None: decodes, see module doc).
MALFORMED: dict[str, type[WireError] | None] = {
    "random_bytes": BadMagic,
    "truncated_header": Truncated,
    "truncated_samples": Truncated,
    "wrong_length": LengthMismatch,
    "huge_count": Truncated,  # a header declaring 4·10⁹ samples on a short payload
    "nonfinite": None,
    "bad_fs": BadHeaderValue,
    "bad_dtype": BadHeaderValue,
    "bad_unit": BadHeaderValue,
    "bad_magic": BadMagic,
    "bad_version": UnsupportedVersion,
    "bad_header_length": BadHeaderValue,
}
#: Well-formed kinds: they decode, with a sequence number already seen on the channel.
WELL_FORMED = ("replay", "duplicate", "clock_past", "clock_future")
#: Forged kinds: new sequence numbers, implausible (module docstring).
FORGED = ("seq_2_63", "seq_jump_100000", "next_in_2100")
KINDS = (*MALFORMED, *WELL_FORMED, *FORGED)

#: 2100-01-01T00:00:00Z in ns since the Unix epoch.
YEAR_2100_NS = 4_102_444_800 * 10**9
_HOUR_NS = 3600 * 10**9
# header field offsets (see millwatch.ingest.wire)
_VERSION, _HEADER_LEN, _FS, _DTYPE, _UNIT, _N = 4, 6, 16, 32, 33, 36


def _patched(payload: bytes, offset: int, fmt: str, value: object) -> bytes:
    out = bytearray(payload)
    struct.pack_into(fmt, out, offset, value)
    return bytes(out)


class HostileChannel:
    """Hostile payloads for one channel: call :meth:`sent` with each valid payload published on
    it, then :meth:`make` a payload of any kind of :data:`KINDS` (at least one valid block must
    have been sent). Keeps the last ``history`` valid payloads (bounded)."""

    def __init__(self, rng: random.Random, history: int = 64) -> None:
        self.rng = rng
        self._sent: deque[bytes] = deque(maxlen=history)

    def sent(self, payload: bytes) -> None:
        self._sent.append(payload)

    @property
    def last(self) -> bytes:
        if not self._sent:
            raise ValueError("no valid block sent on this channel yet")
        return self._sent[-1]

    def make(self, kind: str) -> bytes:
        """One payload of ``kind``."""
        if kind not in KINDS:
            raise ValueError(f"unknown hostile kind {kind!r}; known: {', '.join(KINDS)}")
        payload: bytes = getattr(self, "_" + kind)()
        return payload

    # ---------------------------------------------------------------- malformed
    def _random_bytes(self) -> bytes:
        n = self.rng.randrange(0, 2 * len(self.last))
        body = self.rng.randbytes(n)
        return b"\x00" + body  # never starts like MAGIC, so the decoder's first check fails

    def _truncated_header(self) -> bytes:
        return self.last[: self.rng.randrange(6, HEADER_SIZE)]

    def _truncated_samples(self) -> bytes:
        return self.last[: self.rng.randrange(HEADER_SIZE, len(self.last))]

    def _wrong_length(self) -> bytes:
        return self.last + self.rng.randbytes(self.rng.randrange(1, 16))

    def _huge_count(self) -> bytes:
        return _patched(self.last, _N, "<I", 4_000_000_000)

    def _nonfinite(self) -> bytes:
        block = decode_block(self.rng.choice(self._sent))
        pattern = np.array([np.nan, np.inf, -np.inf], dtype=block.samples.dtype)
        bad = pattern[np.arange(block.samples.shape[0]) % 3]
        return encode_block(bad, block.t0_ns, block.fs, block.seq, block.unit, block.dtype)

    def _bad_fs(self) -> bytes:
        return _patched(self.last, _FS, "<d", self.rng.choice([0.0, -1000.0, np.nan, np.inf]))

    def _bad_dtype(self) -> bytes:
        return _patched(self.last, _DTYPE, "<B", self.rng.choice([0, 5, 9, 255]))

    def _bad_unit(self) -> bytes:
        return _patched(self.last, _UNIT, "<B", self.rng.choice([0, 6, 99, 255]))

    def _bad_magic(self) -> bytes:
        magic = self.rng.choice([b"XXXX", b"MWBL", b"\x00\x00\x00\x00", MAGIC[::-1]])
        return magic + self.last[4:]

    def _bad_version(self) -> bytes:
        return _patched(self.last, _VERSION, "<H", self.rng.choice([0, 2, 9, 65535]))

    def _bad_header_length(self) -> bytes:
        return _patched(self.last, _HEADER_LEN, "<H", self.rng.randrange(0, HEADER_SIZE))

    # ---------------------------------------------------------------- well-formed
    def _replay(self) -> bytes:
        older = list(self._sent)[:-1] or [self.last]
        return self.rng.choice(older)

    def _duplicate(self) -> bytes:
        return self.last

    def _clock_past(self) -> bytes:
        return self._retimed(-self.rng.randrange(2, 12) * _HOUR_NS)

    def _clock_future(self) -> bytes:
        block = decode_block(self.last)
        return self._retimed(YEAR_2100_NS + self.rng.randrange(0, _HOUR_NS) - block.t0_ns)

    # ---------------------------------------------------------------- forged
    def _seq_2_63(self) -> bytes:
        return self._forged(2**63, 1)

    def _seq_jump_100000(self) -> bytes:
        return self._forged(decode_block(self.last).seq + 100_000, 1)

    def _next_in_2100(self) -> bytes:
        block = decode_block(self.last)
        return self._forged(block.seq + 1, 0, YEAR_2100_NS + self.rng.randrange(0, _HOUR_NS))

    def _forged(self, seq: int, steps: int, t0_ns: int | None = None) -> bytes:
        """The last block's samples with sequence number ``seq`` and t0 ``t0_ns`` (default:
        ``steps`` blocks after the last one's)."""
        head = list(HEADER.unpack_from(self.last))
        block = decode_block(self.last)
        head[3] = block.t0_ns + steps * block.duration_ns if t0_ns is None else t0_ns
        head[5] = seq
        return HEADER.pack(*head) + self.last[HEADER_SIZE:]

    def _retimed(self, shift_ns: int) -> bytes:
        """The last block again (same sequence number and samples), its t0 moved by
        ``shift_ns``."""
        head = HEADER.unpack_from(self.last)
        t0 = head[3] + shift_ns
        return HEADER.pack(*head[:3], t0, *head[4:]) + self.last[HEADER_SIZE:]


def kind_cycle(kinds: Sequence[str], rng: random.Random) -> Iterator[str]:
    """The kinds in a fresh random order each round, forever: every kind equally often."""
    order = list(kinds)
    while True:
        rng.shuffle(order)
        yield from order
