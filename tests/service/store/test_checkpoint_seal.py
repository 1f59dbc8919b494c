"""Checkpoints sealed with their checksum: intact ones open, damaged ones are refused saying
what is wrong, older unsealed ones still open (unverified), and the store falls back to the
previous kept checkpoint of a mill whose newest is damaged."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from millwatch.store.checkpoint_seal import CheckpointDamaged, seal, unseal
from millwatch.store.database import Store

POSITION = json.dumps({"file": "millwatch_20261126T000000Z.mcap", "index": 812})
STATE = json.dumps({"pipelines": {"m1": {"damage": [1.25e-9, 3.0e-7], "samples": 96754}}})


def test_a_sealed_checkpoint_opens_as_written() -> None:
    opened = unseal(POSITION, seal(POSITION, STATE))
    assert opened.sealed
    assert (opened.position, opened.state) == (json.loads(POSITION), json.loads(STATE))


def test_a_checkpoint_without_checksum_opens_unverified() -> None:
    opened = unseal(POSITION, STATE)
    assert not opened.sealed and opened.state == json.loads(STATE)


@pytest.mark.parametrize(
    ("damage", "reason"),
    [
        (lambda s: s[:-20], "it is truncated: "),
        (lambda s: s + "0", "it is longer than written"),
        (lambda s: s.replace("96754", "96755"), "SHA-256 checksum does not match"),
        (lambda s: s[:30], "it is truncated within its header"),
        (lambda s: "x" + s, "its header is damaged"),
        (lambda s: s.replace("checkpoint 1 ", "checkpoint 7 "), "format version 7"),
        (lambda s: STATE[:-3], "its snapshot is not valid JSON ("),  # unsealed, truncated
        (lambda s: "", "its header is damaged"),
    ],
)
def test_damage_is_refused_saying_what_is_wrong(damage, reason: str) -> None:
    with pytest.raises(CheckpointDamaged, match=reason.replace("(", r"\(")):
        unseal(POSITION, damage(seal(POSITION, STATE)))


def test_a_changed_position_is_refused() -> None:
    moved = json.dumps({"file": "millwatch_20261126T000000Z.mcap", "index": 813})
    with pytest.raises(CheckpointDamaged, match="checksum"):
        unseal(moved, seal(POSITION, STATE))


@given(st.data())
def test_every_single_bit_flip_is_refused(data: st.DataObject) -> None:
    """One flipped bit anywhere in the stored text — header, checksum, JSON — never opens."""
    stored = seal(POSITION, STATE).encode()
    at = data.draw(st.integers(0, len(stored) - 1), label="byte")
    bit = data.draw(st.integers(0, 6), label="bit")  # (ASCII: bit 7 makes invalid UTF-8)
    flipped = bytearray(stored)
    flipped[at] ^= 1 << bit
    with pytest.raises(CheckpointDamaged):
        unseal(POSITION, flipped.decode())


def _put(store: Store, part: str, index: int, state: dict) -> None:
    with store.transaction() as db:
        Store.put_checkpoint(db, part, 1_000 + index, {"file": "a.mcap", "index": index}, state)


def _set_state(store: Store, row_id: int, text: str) -> None:
    with store.transaction() as db:
        db.execute("UPDATE checkpoint_parts SET state_json = ? WHERE id = ?", (text, row_id))


def _rows(store: Store, part: str) -> list[tuple[int, str]]:
    sql = "SELECT id, state_json FROM checkpoint_parts WHERE part = ? ORDER BY id DESC"
    return [(i, s) for i, s in store._query(sql, (part,))]


def test_the_store_falls_back_to_the_previous_intact_checkpoint(tmp_path: Path) -> None:
    with Store(tmp_path / "mw.db") as store:
        for i in range(3):
            _put(store, "m1", i, {"n": i})
            _put(store, "m2", i, {"n": 10 + i})
        (newest, text), (previous, _) = _rows(store, "m1")  # two kept
        _set_state(store, newest, text[:-3])
        choice = store.choose_checkpoints()
        assert choice.parts == {"m1": ({"file": "a.mcap", "index": 1}, {"n": 1}),
                                "m2": ({"file": "a.mcap", "index": 2}, {"n": 12})}  # fmt: skip
        [refused] = choice.refused
        assert (refused.part, refused.checkpoint_id, refused.created_ns) == ("m1", newest, 1002)
        assert refused.reason.startswith("it is truncated")
        assert choice.chosen["m1"] == (previous, 1001) and choice.unsealed == []
        assert store.latest_checkpoints() == choice.parts


def test_a_part_with_no_intact_checkpoint_has_none(tmp_path: Path) -> None:
    with Store(tmp_path / "mw.db") as store:
        for i in range(2):
            _put(store, "m1", i, {"n": i})
        for row_id, text in _rows(store, "m1"):
            _set_state(store, row_id, text.replace('"n": ', '"n":9'))  # same length
        _put(store, "m2", 0, {"n": 5})
        choice = store.choose_checkpoints()
        assert list(choice.parts) == ["m2"]
        assert [r.part for r in choice.refused] == ["m1", "m1"]
        assert all("checksum" in r.reason for r in choice.refused)


def test_an_unsealed_checkpoint_of_an_older_millwatch_is_taken_and_said_so(tmp_path) -> None:
    with Store(tmp_path / "mw.db") as store:
        _put(store, "m1", 0, {"n": 0})
        [(row_id, _)] = _rows(store, "m1")
        _set_state(store, row_id, json.dumps({"n": 0}))
        choice = store.choose_checkpoints()
        assert choice.parts["m1"][1] == {"n": 0} and choice.unsealed == ["m1"]


def test_a_row_that_is_no_longer_utf8_is_refused_not_raised(tmp_path: Path) -> None:
    """The high bit of one byte flipped on disk: SQLite hands back text Python cannot decode."""
    with Store(tmp_path / "mw.db") as store:
        for i in range(2):
            _put(store, "m1", i, {"n": i})
        (newest, text), _ = _rows(store, "m1")
        raw = bytearray(text.encode())
        raw[len(raw) // 2] ^= 0x80
        with store.transaction() as db:
            db.execute("UPDATE checkpoint_parts SET state_json = CAST(? AS TEXT) WHERE id = ?",
                       (bytes(raw), newest))  # fmt: skip
        choice = store.choose_checkpoints()
        assert choice.parts["m1"][1] == {"n": 0}
        [refused] = choice.refused
        assert refused.reason.startswith("it cannot be read (")
