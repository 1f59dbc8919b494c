"""One alarm record: the API's alarm bodies and the store's tables carry exactly the fields of
:mod:`millwatch.alarms.lifecycle`'s records, so a field added to the record and missed in the API
model or in a migration fails here, naming it."""

from __future__ import annotations

import dataclasses
import sqlite3

from millwatch.alarms.lifecycle import Alarm, Comment, TransitionRecord
from millwatch.analytics.drivetrain.mill_config import MillConfig
from millwatch.api.models import (
    ALARM_ENTRY_EXAMPLE,
    ALARM_EXAMPLE,
    AlarmDetail,
    AlarmOut,
    CommentOut,
    TransitionOut,
)
from millwatch.api.routes.params import MILL_ID_PATTERN
from millwatch.store.database import Store
from millwatch.store.records import columns


def _iso_beside_ns(names: tuple[str, ...]) -> tuple[str, ...]:
    """The body's fields: each ``<name>_ns`` followed by its ISO-8601 ``<name>``."""
    return tuple(f for n in names for f in ((n, n[:-3]) if n.endswith("_ns") else (n,)))


def test_the_alarm_bodies_have_the_fields_of_the_records_in_their_order():
    alarm = (*_iso_beside_ns(columns(Alarm)), "shelved")  # (shelved: computed, Alarm.to_dict)
    assert tuple(AlarmOut.model_fields) == (*alarm, "comments")
    assert tuple(ALARM_EXAMPLE) == alarm
    assert tuple(ALARM_ENTRY_EXAMPLE) == (*alarm, "comments")
    assert tuple(TransitionOut.model_fields) == _iso_beside_ns(columns(TransitionRecord))
    assert tuple(AlarmDetail.model_fields) == (*alarm, "comments", "transitions")


def test_a_comment_body_has_the_fields_of_the_comment_record():
    names = tuple(f.name for f in dataclasses.fields(Comment))
    assert set(CommentOut.model_fields) == set(_iso_beside_ns(names))
    example = ALARM_ENTRY_EXAMPLE["comments"][0]
    assert Comment.from_dict(example).to_dict() == {k: example[k] for k in names}


def test_the_alarm_as_plain_data_is_what_the_body_lists():
    fields = tuple(Alarm.from_dict(ALARM_EXAMPLE).to_dict())
    assert fields == tuple(f for f in ALARM_EXAMPLE if f in fields)
    assert set(ALARM_EXAMPLE) - set(fields) == {"raised", "updated", "acked", "cleared",
                                                "confirmed_at", "shelved_until",
                                                "last_commented"}  # fmt: skip


def test_the_alarm_tables_have_the_columns_of_the_records(tmp_path):
    Store(tmp_path / "s.db").close()
    db = sqlite3.connect(tmp_path / "s.db")
    for table, record in (("alarms", Alarm), ("alarm_transitions", TransitionRecord)):
        names = {row[1] for row in db.execute(f"PRAGMA table_info({table})")}
        assert names == set(columns(record)), table
    db.close()


def test_a_mill_id_path_parameter_accepts_what_a_mill_config_may_be_called():
    assert MillConfig.model_json_schema()["properties"]["id"]["pattern"] == MILL_ID_PATTERN
