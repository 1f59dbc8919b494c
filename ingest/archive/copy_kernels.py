"""Copying byte ranges between numpy arrays inside compiled kernels, as one ``memcpy`` each.

numba compiles ``out[a:b] = buf[c:d]`` on ``uint8`` arrays to a byte-at-a-time loop: ~200 ns
for a 420-byte block payload, the main cost of packing a batch's payloads for another process
(:meth:`millwatch.ingest.archive.batches.MessageBatch.compact`) or gathering a mill's samples
(:mod:`millwatch.worker.batch_lane`). :func:`copy_bytes` emits LLVM's ``memcpy`` instead (~25–50
ns), with the bounds checked first.
"""

from __future__ import annotations

from numba import njit, types
from numba.core import cgutils
from numba.extending import intrinsic

__all__ = ["copy_bytes"]


@intrinsic
def _memcpy(typingctx, dst, dst_at, src, src_at, n):
    """``memcpy(&dst[dst_at], &src[src_at], n)`` on contiguous 1-D uint8 arrays (unchecked)."""
    sig = types.void(dst, types.intp, src, types.intp, types.intp)

    def codegen(context, builder, signature, args):
        dst_v, dst_at_v, src_v, src_at_v, n_v = args
        d = context.make_array(signature.args[0])(context, builder, dst_v)
        s = context.make_array(signature.args[2])(context, builder, src_v)
        to = builder.gep(d.data, [dst_at_v])
        frm = builder.gep(s.data, [src_at_v])
        cgutils.raw_memcpy(builder, to, frm, n_v, 1)
        return context.get_dummy_value()

    return sig, codegen


@njit(cache=True, nogil=True, inline="always")
def copy_bytes(dst, dst_at, src, src_at, n):
    """Copy ``src[src_at : src_at + n]`` to ``dst[dst_at : dst_at + n]`` (contiguous 1-D
    ``uint8`` arrays, not overlapping); IndexError when a range leaves its array."""
    if n < 0 or dst_at < 0 or src_at < 0 or dst_at + n > dst.shape[0] or src_at + n > src.shape[0]:
        raise IndexError("byte range outside the array")
    if n:
        _memcpy(dst, dst_at, src, src_at, n)  # type: ignore[call-arg]  # numba supplies typingctx
