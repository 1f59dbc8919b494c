"""What a zenoh callback may queue at all: the worker's first gate, before the archive.

A subscriber on a mill's keys (``millwatch/v1/<site>/<mill>/*``) receives whatever any peer
puts under that prefix. Two kinds of payload are refused here, in the callback, so they cost
neither queue room nor archive space (README "Admission"):

* **oversize**: a payload longer than ``[worker] max_block_bytes`` (a 40 MB block was
  archived whole, issue 26);
* **unknown key**: a key under the prefix that is none of the mill's configured channels
  (each new key used to add a log line and an MCAP channel of its own).

Both are counted per key prefix (:func:`~service.worker.admission.key_prefix`: the mill, so
the counters stay as few as the subscriptions) and logged once per prefix and kind. Everything
else goes on to the queue, the archive and the admission (:mod:`service.worker.admission`),
which judges a block's content against its channel's history. Called from zenoh's threads: the
refusal paths take a lock; the common path only reads.
"""

from __future__ import annotations

import logging
import threading
from collections import Counter
from collections.abc import Callable

from service.worker.admission import key_prefix

__all__ = ["IngressGate"]

log = logging.getLogger(__name__)


class IngressGate:
    """Refuses oversize payloads and keys of no configured channel (module docstring).
    ``route``: key → (mill, channel) or None; ``max_block_bytes``: the largest payload taken."""

    def __init__(
        self, route: Callable[[str], tuple[str, str] | None], max_block_bytes: int
    ) -> None:
        self._route = route
        self.max_block_bytes = max_block_bytes
        #: Refused payloads per key prefix: too large, and on keys of no configured channel.
        self.oversize: Counter[str] = Counter()
        self.unknown: Counter[str] = Counter()
        self._lock = threading.Lock()
        self._logged: set[tuple[str, str]] = set()

    def admit(self, key: str, payload: bytes) -> bool:
        """Whether the payload on ``key`` may be queued (refusals counted, logged once)."""
        size = len(payload)
        if size > self.max_block_bytes:
            if self._refuse(self.oversize, key, "oversize"):
                log.warning("%s: block of %d bytes refused (more than [worker] max_block_bytes "
                            "= %d; counted under %s, further ones not logged)", key, size,
                            self.max_block_bytes, key_prefix(key))  # fmt: skip
            return False
        if self._route(key) is None:
            if self._refuse(self.unknown, key, "unknown"):
                log.warning("%s: no configured channel has this key; its blocks are refused "
                            "(counted under %s, further keys there not logged)", key,
                            key_prefix(key))  # fmt: skip
            return False
        return True

    @property
    def refused(self) -> int:
        """Payloads refused, in all."""
        return sum(self.oversize.values()) + sum(self.unknown.values())

    def _refuse(self, counter: Counter[str], key: str, kind: str) -> bool:
        """Count a refusal under ``key``'s prefix; whether it is the first of its prefix and
        kind (to be logged)."""
        prefix = key_prefix(key)
        with self._lock:
            counter[prefix] += 1
            first = (prefix, kind) not in self._logged
            self._logged.add((prefix, kind))
        return first
