"""The alarm journal: every stored transition of the alarms, in time order, by mill and time.

``GET /alarms/journal?mill=&from=&to=&after=&limit=`` (:mod:`millwatch.api.routes.journal`)
answers the ISA-18.2 alarm journal from the store's ``alarm_transitions`` table, each
transition with its alarm's mill, rule, subject, quantity and unit beside it — every column a
transition has (who acknowledged, a comment), whatever the kind (raised, acknowledged,
cleared, …). ``/alarms`` is the alarms' *current* state; this is their *history*.

* **Order and paging** — by ``(t_ns, alarm_id, seq)`` (:class:`JournalKey`), a total order;
  a page holds at most ``limit`` entries, and ``next`` (the last entry's key, as text) is passed
  back as ``after=`` for the following page (``null``: there is no more). Keyset paging: a page
  never repeats or skips an entry, however many are written meanwhile *later* in time.
* **Time** — ``from`` ≤ ``t_ns`` < ``to`` (integer ns UTC or ISO-8601). A transition's time is
  the mill's sample time, an acknowledgement's the wall clock: the journal is history by time,
  not a feed of changes (an entry stored late with an earlier time lands on an earlier page).
  To follow changes, poll ``/alarms`` with its change cursor (:mod:`millwatch.api.alarm_board`).
* **Where it comes from** — in process, the store (:func:`journal_entries`, one query; no index
  on time: a year of 200 000 transitions scans in about 0.1 s). Under ``millwatch api`` each
  mill's worker answers its own entries (the ``journal`` question of
  :mod:`millwatch.remote.protocol`), at most ``limit + 1`` each, and the API merges them in order
  (:func:`merge_pages`); mills whose worker does not answer are listed in ``unreachable``, so a
  partial journal says so.
"""

from __future__ import annotations

import heapq
import re
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

from millwatch.alarms.lifecycle import TransitionRecord
from millwatch.api.times import with_iso
from millwatch.store.database import Store
from millwatch.store.records import from_row

__all__ = [
    "ALARM_COLUMNS",
    "JOURNAL_KEY_PATTERN",
    "JournalKey",
    "JournalPage",
    "JournalQuery",
    "journal_body",
    "journal_entries",
    "merge_pages",
]

INT64_MAX = 2**63 - 1
ALARM_COLUMNS = ("mill_id", "rule", "subject", "quantity", "unit", "simulated")
"""The alarm's columns given beside each of its transitions."""
JOURNAL_KEY_PATTERN = r"^[0-9]{1,19}:[0-9]{1,9}:.{1,200}$"
"""What ``after=`` looks like: ``<t_ns>:<seq>:<alarm_id>`` (a page's ``next``)."""
_KEY = re.compile(JOURNAL_KEY_PATTERN)


@dataclass(frozen=True, slots=True, order=True)
class JournalKey:
    """The journal's order: time (ns UTC), then alarm id, then the alarm's ``seq``."""

    t_ns: int
    alarm_id: str
    seq: int

    def __str__(self) -> str:
        return f"{self.t_ns}:{self.seq}:{self.alarm_id}"

    @classmethod
    def parse(cls, text: str) -> JournalKey:
        """The key ``"<t_ns>:<seq>:<alarm_id>"``; ``ValueError`` naming the text otherwise."""
        if not _KEY.match(text):
            raise ValueError(f"{text[:40]!r} is not a journal position (<t_ns>:<seq>:<alarm id>)")
        t_ns, seq, alarm_id = text.split(":", 2)
        return cls(int(t_ns), alarm_id, int(seq))

    @classmethod
    def of(cls, entry: dict[str, Any]) -> JournalKey:
        """The key of one journal entry."""
        return cls(entry["t_ns"], entry["alarm_id"], entry["seq"])


@dataclass(frozen=True, slots=True)
class JournalQuery:
    """What a journal page asks: one mill or all (``mill_id`` None), ``from_ns`` ≤ t <
    ``to_ns`` (ns UTC), after ``after`` (a previous page's last key), at most ``limit``."""

    mill_id: str | None = None
    from_ns: int = 0
    to_ns: int = INT64_MAX
    after: JournalKey | None = None
    limit: int = 500


@dataclass(frozen=True, slots=True)
class JournalPage:
    """A backend's answer: entries in journal order (up to ``limit + 1``: the one beyond says
    there is more) and the mills that did not answer."""

    entries: list[dict[str, Any]]
    unreachable: list[str]


def journal_entries(store: Store, query: JournalQuery) -> list[dict[str, Any]]:
    """The store's entries of ``query``, in journal order, at most ``limit + 1``: each
    transition's own fields (:class:`~millwatch.alarms.lifecycle.TransitionRecord`'s, whatever they
    are) and its alarm's :data:`ALARM_COLUMNS`."""
    after = query.after
    rows = store.alarm_journal(
        query.mill_id, query.from_ns, query.to_ns,
        None if after is None else (after.t_ns, after.alarm_id, after.seq), query.limit + 1,
    )  # fmt: skip
    out = []
    for row in rows:
        entry = from_row(TransitionRecord, row).to_row()
        entry.update({c: row[c] for c in ALARM_COLUMNS})
        entry["simulated"] = bool(entry["simulated"])
        out.append(entry)
    return out


def merge_pages(pages: Iterable[list[dict[str, Any]]], limit: int) -> list[dict[str, Any]]:
    """Pages of several mills (each in journal order) as one, in order, at most ``limit + 1``."""
    merged = heapq.merge(*pages, key=JournalKey.of)
    return [entry for _, entry in zip(range(limit + 1), merged, strict=False)]


def journal_body(page: JournalPage, limit: int) -> dict[str, Any]:
    """``GET /alarms/journal``'s answer: the first ``limit`` entries (ISO-8601 beside every
    ``*_ns``), ``next`` (the last one's key when there are more), ``unreachable``."""
    entries = page.entries[:limit]
    more = len(page.entries) > limit and entries
    return {
        "entries": with_iso(entries),
        "count": len(entries),
        "next": str(JournalKey.of(entries[-1])) if more else None,
        "unreachable": sorted(page.unreachable),
    }
