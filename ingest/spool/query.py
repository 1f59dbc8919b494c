"""Recovery from a spool over zenoh: the gateway's queryable and the worker's client.

Zenoh has the tool (DESIGN "Scale": queryables, not a home-made protocol): a spool declares a
queryable on :func:`millwatch.ingest.keys.spool_key` of each channel it holds, and answers a
``get`` with selector parameters ``first=<seq>;last=<seq>[;max=<n>]`` by

- one reply per block it holds in ``first..last``, in ``seq`` order, payload = the wire block
  byte-identical, encoding the block encoding
  (:func:`millwatch.ingest.zenoh_session.block_encoding`);
- then one closing reply, encoding ``application/json``:
  ``{"first": …, "last": …, "through": …, "blocks": n, "dropped": d}`` — ``through`` is the last
  sequence number the answer covers (``last``, or less when ``max`` cut it short: ask again
  from ``through + 1``), ``dropped`` how many sequence numbers of ``first..through`` the spool's
  retention removed (exact; :attr:`millwatch.ingest.spool.store.Spool.dropped_blocks`).

Numbers in the range that are neither returned nor dropped were never spooled: the gateway was
down when they fell due (or never sent them). A query uses no consolidation (every reply shares
one key; zenoh's default would keep only the latest).

:func:`fetch_spooled` is the client: it pages through a range and returns the blocks in order
with the dropped count; no spool for the key means an empty answer at once, never a hang.
"""

from __future__ import annotations

import json
import logging
import threading
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Any, Protocol

import zenoh

from millwatch.ingest.keys import parse_spool_key, spool_key
from millwatch.ingest.spool.store import SpoolRead, payload_seq
from millwatch.ingest.zenoh_session import block_encoding

__all__ = ["PAGE_BLOCKS", "SpoolAnswer", "SpoolServer", "SpoolSource", "fetch_spooled"]

log = logging.getLogger(__name__)

#: Blocks per query page (~1 MB of 1 kHz float32 blocks): bounded replies in flight.
PAGE_BLOCKS = 2000
#: The closing reply's encoding.
SUMMARY_ENCODING = "application/json"


@dataclass(frozen=True, slots=True)
class SpoolAnswer:
    """What the spools of a channel hold of a range: ``blocks`` (wire payloads, ``seq`` order,
    each once), ``dropped`` (sequence numbers retention removed: exact), ``answered`` (a spool
    replied; False: no spool holds the channel, or none answered in time)."""

    blocks: list[bytes]
    dropped: int
    answered: bool


class SpoolSource(Protocol):
    """What a :class:`SpoolServer` answers from: a :class:`~millwatch.ingest.spool.store.Spool` on
    disk or a gateway's :class:`~millwatch.ingest.spool.recent.RecentBlocks` in memory."""

    on_new_key: Callable[[str], None] | None

    def spooled_keys(self) -> list[str]: ...

    def read(self, key: str, first: int, last: int, limit: int | None = None) -> SpoolRead: ...

    def dropped(self, key: str, first: int | None = None, last: int | None = None) -> int: ...


class SpoolServer:
    """Answers recovery queries from ``spool`` on ``session`` (module docstring): a queryable
    per key the spool holds, declared for new keys as they are spooled. Queries are answered
    on one worker thread of its own (reading files must not hold a zenoh thread)."""

    def __init__(self, session: zenoh.Session, spool: SpoolSource) -> None:
        self._session = session
        self._spool = spool
        self._pool = ThreadPoolExecutor(1, thread_name_prefix="millwatch-spool")
        self._lock = threading.Lock()
        self._queryables: dict[str, Any] = {}
        self.answered = 0
        for key in spool.spooled_keys():
            self.declare(key)
        spool.on_new_key = self.declare

    def declare(self, key: str) -> None:
        """Answer queries about channel ``key`` (idempotent)."""
        with self._lock:
            if key in self._queryables:
                return
            try:
                where = spool_key(key)
            except ValueError:
                log.warning("spool: %r is not a channel key; its blocks are not served", key)
                return
            self._queryables[key] = self._session.declare_queryable(where, self._submit)

    def _submit(self, query: zenoh.Query) -> None:
        self._pool.submit(self._answer, query)

    def _answer(self, query: zenoh.Query) -> None:
        try:
            key = parse_spool_key(str(query.key_expr))
            first, last, limit = _range(query.parameters)
            found = self._spool.read(key, first, last, limit)
            through = last
            if limit is not None and len(found.blocks) >= limit:
                cut = payload_seq(found.blocks[-1])
                through = last if cut is None else cut
            encoding = block_encoding()
            for payload in found.blocks:
                query.reply(str(query.key_expr), payload, encoding=encoding)
            dropped = self._spool.dropped(key, first, through)
            summary = {"first": first, "last": last, "through": through,
                       "blocks": len(found.blocks), "dropped": dropped}  # fmt: skip
            query.reply(str(query.key_expr), json.dumps(summary).encode(),
                        encoding=zenoh.Encoding(SUMMARY_ENCODING))  # fmt: skip
            self.answered += 1
        except ValueError as exc:
            query.reply_err(str(exc).encode())
        except Exception:
            log.exception("spool: query %s failed", query.selector)
        finally:
            query.drop()

    def close(self) -> None:
        """Stop answering."""
        with self._lock:
            for queryable in self._queryables.values():
                try:
                    queryable.undeclare()
                except zenoh.ZError as exc:  # a closed session already undeclared it
                    log.debug("spool queryable undeclare failed: %s", exc)
            self._queryables.clear()
        self._pool.shutdown(wait=True, cancel_futures=True)


def _range(parameters: Any) -> tuple[int, int, int | None]:
    """``first``, ``last`` and ``max`` of a query's parameters; ValueError naming the bad one."""
    values: dict[str, int | None] = {}
    for name in ("first", "last", "max"):
        text = parameters.get(name)
        if text is None:
            if name == "max":
                values[name] = None
                continue
            raise ValueError(f"spool query: parameter {name!r} (a sequence number) is missing")
        try:
            values[name] = int(text)
        except ValueError as exc:
            raise ValueError(f"spool query: {name}={text!r} is not an integer") from exc
    first, last, limit = values["first"], values["last"], values["max"]
    if first is None or last is None or first < 0 or last < first:
        raise ValueError(f"spool query: range {first}..{last} is not 0 <= first <= last")
    if limit is not None and limit < 1:
        raise ValueError(f"spool query: max={limit} must be >= 1")
    return first, last, limit


def fetch_spooled(
    session: zenoh.Session,
    channel_key: str,
    first_seq: int,
    last_seq: int,
    timeout: float = 10.0,
    *,
    page: int = PAGE_BLOCKS,
) -> SpoolAnswer:
    """The blocks of channel key ``channel_key`` with ``first_seq <= seq <= last_seq`` the
    spools hold, in ``seq`` order, and how many of the range their retention dropped; each page
    of at most ``page`` blocks waits at most ``timeout`` s. Several spools (a gateway's and a
    forwarder's) are merged: each block once, the smallest dropped count."""
    blocks: dict[int, bytes] = {}
    dropped, answered, at = 0, False, first_seq
    for _ in range((last_seq - first_seq) // max(page, 1) + 2):  # (bounded: pages advance)
        if at > last_seq:
            break
        got, through, page_dropped = _page(session, channel_key, at, last_seq, timeout, page)
        if through is None:
            break
        answered = True
        blocks.update(got)
        dropped += page_dropped
        at = through + 1
    return SpoolAnswer([blocks[s] for s in sorted(blocks)], dropped, answered)


def _page(
    session: zenoh.Session, key: str, first: int, last: int, timeout: float, page: int
) -> tuple[dict[int, bytes], int | None, int]:
    """One query: blocks by seq, the lowest ``through`` of the spools that answered (None:
    none), the smallest dropped count."""
    selector = (
        spool_key(key)
        + "?"
        + ";".join(("first=" + str(first), "last=" + str(last), "max=" + str(page)))
    )
    blocks: dict[int, bytes] = {}
    throughs: list[int] = []
    dropped: list[int] = []
    replies = session.get(selector, consolidation=zenoh.ConsolidationMode.NONE, timeout=timeout)
    for reply in replies:
        sample = reply.ok
        if sample is None:
            log.warning("spool query %s refused: %s", selector, _error_text(reply))
            continue
        payload = sample.payload.to_bytes()
        if str(sample.encoding).startswith(SUMMARY_ENCODING):
            summary = json.loads(payload)
            throughs.append(int(summary["through"]))
            dropped.append(int(summary["dropped"]))
            continue
        seq = payload_seq(payload)
        if seq is not None and first <= seq <= last:
            blocks[seq] = payload
    if not throughs:
        return blocks, None, 0
    return blocks, min(throughs), min(dropped)


def _error_text(reply: zenoh.Reply) -> str:
    err = reply.err
    return "?" if err is None else err.payload.to_bytes().decode(errors="replace")[:200]
