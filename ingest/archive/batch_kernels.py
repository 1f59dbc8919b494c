"""Compiled kernels of the batch reader (:mod:`millwatch.ingest.archive.batches`): byte-level scans
of MCAP records and the packing of payloads, each a loop over bytes or records that numba compiles.

MCAP spec: records are ``opcode u8, length u64 (little-endian), body``; a Message body starts
``channel_id u16, sequence u32, log_time u64, publish_time u64``, then the data.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from millwatch.ingest.archive.copy_kernels import copy_bytes

__all__ = ["message_heads", "pack_ranges", "record_bounds"]


@njit(cache=True, nogil=True)
def pack_ranges(buf, offset, length, total):
    """The byte ranges ``buf[offset[k] : offset[k] + length[k]]``, back to back."""
    out = np.empty(total, dtype=np.uint8)
    at = 0
    for k in range(offset.shape[0]):
        copy_bytes(out, at, buf, offset[k], length[k])
        at += length[k]
    return out


@njit(cache=True, nogil=True)
def message_heads(data, starts, lengths, known, channel, log_time):
    """Channel id (u16) and log time (u64, little-endian) of each message record body at
    ``starts``; returns how many lead the records before the first invalid one (too short
    for the message header, or on a channel id not in ``known``), whose channel is set."""
    size = 22  # channel u16, sequence u32, log_time u64, publish_time u64
    for k in range(starts.shape[0]):
        if lengths[k] < size:
            return k
        a = starts[k]
        c = np.int64(data[a]) | (np.int64(data[a + 1]) << 8)
        channel[k] = c
        if not known[c]:
            return k
        t = np.uint64(0)
        for i in range(8):
            t |= np.uint64(data[a + 6 + i]) << np.uint64(8 * i)
        log_time[k] = np.int64(t)
    return starts.shape[0]


@njit(cache=True, nogil=True)
def record_bounds(data, pos, ops, starts, lengths):
    """Record boundaries from ``pos``; status 0 ok, 1 torn header, 2 torn body."""
    end = data.shape[0]
    n = 0
    while pos < end:
        if pos + 9 > end:
            return n, 1
        length = np.int64(0)
        for i in range(8):
            length |= np.int64(data[pos + 1 + i]) << (8 * i)
        if length < 0 or length > end - pos - 9:
            return n, 2
        ops[n] = data[pos]
        starts[n] = pos + 9
        lengths[n] = length
        n += 1
        pos += 9 + length
    return n, 0
