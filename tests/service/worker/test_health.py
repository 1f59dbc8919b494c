"""Channel health: sequence gaps, repeats, lag and staleness."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from millwatch.ingest.wire import Unit, decode_block, encode_block
from millwatch.worker.health import ChannelHealth, MillHealth


def block(seq: int, t0: int = 0, n: int = 100, bad: int = 0):
    x = np.zeros(n)
    x[:bad] = np.nan
    return decode_block(encode_block(x, t0, 1000.0, seq, Unit.MEGAPASCAL))


def test_sequence_numbers_reveal_gaps_and_repeats():
    h = ChannelHealth()
    verdicts = [h.observe(block(s, t0=s * 100_000_000), recv_ns=0) for s in (0, 1, 2, 5, 5, 6)]
    assert verdicts == ["first", "next", "next", "gap", "duplicate", "next"]
    assert (h.gaps, h.missing_blocks, h.repeats, h.blocks, h.samples) == (1, 2, 1, 5, 500)


def test_a_replayed_block_never_moves_the_channel_back():
    """The 102,762 'missing' blocks of issue 16: a replay of an old block must not make the next
    valid block look like a gap."""
    h = ChannelHealth()
    for s in range(10):
        h.observe(block(s, t0=s * 100_000_000), recv_ns=0)
    for old in (3, 9, 0, 9):
        assert h.observe(block(old), recv_ns=0) in {"replay", "duplicate"}
    assert h.observe(block(10, t0=1_000_000_000), recv_ns=0) == "next"
    assert (h.missing_blocks, h.gaps, h.duplicates, h.replays, h.last_seq) == (0, 0, 2, 2, 10)


def test_a_gap_names_the_lost_span_with_its_times():
    h = ChannelHealth()
    h.observe(block(4, t0=400_000_000), recv_ns=0)
    later = block(9, t0=900_000_000)
    loss = h.accept(later, recv_ns=0).loss
    assert loss is not None
    assert (loss.first_seq, loss.last_seq, loss.blocks) == (5, 8, 4)
    assert (loss.first_t_ns, loss.last_t_ns) == (500_000_000, 800_000_000)
    assert h.expected_t0(10) == (1_000_000_000, 50_000_000)


def test_counters_survive_a_checkpoint():
    h = ChannelHealth()
    for s in (0, 1, 4, 4, 2):
        h.observe(block(s, t0=s * 100_000_000), recv_ns=0)
    h.decode_error("truncated", recv_ns=0)
    again = ChannelHealth()
    again.restore_counters(h.counters())
    assert again.as_dict(0, 10.0) | {"last_recv_ns": None, "lag_s": None, "stale": True} == (
        h.as_dict(0, 10.0) | {"last_recv_ns": None, "lag_s": None, "stale": True}
    )
    assert again.admit(5) == "next" and again.expected_t0(5) == (500_000_000, 50_000_000)


def test_lag_staleness_and_nonfinite_counts():
    h = ChannelHealth()
    h.observe(block(0, t0=1_000_000_000, bad=3), recv_ns=1_400_000_000)
    d = h.as_dict(now_ns=1_500_000_000, stale_after_s=10.0)
    assert d["lag_s"] == 0.3  # block ends at 1.1 s, received at 1.4 s
    assert d["nonfinite_samples"] == 3 and not d["stale"]
    assert h.stale(now_ns=12_000_000_000, stale_after_s=10.0)


def test_a_mill_lists_its_stale_channels():
    m = MillHealth.for_channels(["speed", "pinion_torque"])
    m.channels["speed"].observe(block(0), recv_ns=0)
    m.channels["pinion_torque"].decode_error("truncated", recv_ns=0)
    assert m.stale_channels(now_ns=5_000_000_000, stale_after_s=10.0) == []
    assert m.stale_channels(now_ns=20_000_000_000, stale_after_s=10.0) == ["speed", "pinion_torque"]
    assert m.as_dict(0, 10.0)["channels"]["pinion_torque"]["decode_errors"] == {"truncated": 1}


def test_per_minute_rate_over_the_last_minute():
    from millwatch.worker.health import PerMinute

    meter = PerMinute()
    s = 1_000_000_000
    assert meter.rate(0, 0) == 0.0
    assert meter.rate(30 * s, 3) == 3.0  # less than a minute seen: counted over a minute
    assert meter.rate(60 * s, 6) == 6.0
    assert meter.rate(120 * s, 6) == 0.0  # nothing new in the last minute


def test_latency_reservoir_reports_quantiles_of_the_kept_blocks():
    from types import SimpleNamespace

    from millwatch.worker.health import LatencyReservoir

    r = LatencyReservoir(size=4)
    assert r.quantiles()["blocks"] == 0
    r.add_batch(10_000_000_000, [SimpleNamespace(recv_ns=t * 1_000_000_000) for t in range(10)])
    q = r.quantiles()
    assert q["blocks"] == 4 and q["max_s"] == 4.0  # only the newest four are kept: 4, 3, 2, 1 s


# ---------------------------------------------------------------- plausibility (issue 26)
STEP = 100_000_000  # 100 samples at 1 kHz
NOW = 1_790_000_000 * 10**9


def _history(n: int = 10) -> ChannelHealth:
    h = ChannelHealth(fs_hz=1000.0)
    for s in range(n):
        h.accept(block(s, t0=NOW - (n - s) * STEP), recv_ns=NOW - (n - s - 1) * STEP)
    return h


def _state(h: ChannelHealth) -> tuple[object, ...]:
    return (h.last_seq, h.last_t0_ns, h.last_sample_ns, h.blocks, h.samples, h.missing_blocks,
            h.gaps, h.clock_faults, h.in_clock_fault)  # fmt: skip


@pytest.mark.parametrize(
    ("seq", "t0", "why"),
    [
        (2**63, NOW, "seq_out_of_range"),
        (2**64 - 1, NOW, "seq_out_of_range"),
        (9 + 100_000, NOW, "seq_ahead"),
        (9 + 100_000, NOW + 100_000 * STEP, "t0_ahead"),
        (10, 4_102_444_800 * 10**9, "t0_ahead"),  # the next seq, t0 in 2100
        (10, 2**63 - 1, "t0_ahead"),
    ],
)
def test_an_implausible_block_is_counted_and_moves_nothing(seq, t0, why):
    h = _history()
    before = _state(h)
    got = h.accept(block(seq, t0=t0), recv_ns=NOW)
    assert (got.verdict, got.block, got.implausible) == ("implausible", None, why)
    assert _state(h) == before and h.implausible == {why: 1}
    assert h.accept(block(10, t0=NOW), recv_ns=NOW + STEP).verdict == "next"
    assert (h.missing_blocks, h.gaps) == (0, 0)


def test_a_foreign_sample_rate_or_no_samples_is_implausible():
    h = _history()
    odd = decode_block(encode_block(np.zeros(100), NOW, 1e-300, 10, Unit.MEGAPASCAL))
    assert h.accept(odd, recv_ns=NOW).implausible == "sample_rate"
    assert h.accept(block(10, t0=NOW, n=0), recv_ns=NOW).implausible == "empty"
    anyrate = ChannelHealth()  # no configured rate (a tool that does not know it): by the clock
    assert anyrate.accept(odd, recv_ns=NOW).implausible == "t0_ahead"


def test_a_long_outage_and_a_late_spool_are_plausible():
    """Legitimate gaps: a gateway down for a day resumes with its sequence number and clock
    (not ahead of the receive time); a spool delivers blocks days late."""
    h = _history()
    day = 864_000  # blocks in a day
    got = h.accept(block(9 + day, t0=NOW + (day - 1) * STEP), recv_ns=NOW + day * STEP)
    assert got.verdict == "gap" and got.loss is not None and got.loss.blocks == day - 1
    late = _history()
    assert late.accept(block(10, t0=NOW), recv_ns=NOW + 5 * 86_400 * 10**9).verdict == "next"


def test_a_clock_ahead_within_max_ahead_is_plausible_and_the_limit_is_configurable():
    from millwatch.worker.health import AdmissionLimits

    h = _history()
    assert h.accept(block(10, t0=NOW + 59 * 10**9), recv_ns=NOW).implausible is None
    strict = ChannelHealth(fs_hz=1000.0, limits=AdmissionLimits(max_ahead_ns=10**9))
    assert strict.accept(block(0, t0=NOW + 2 * 10**9), recv_ns=NOW).implausible == "t0_ahead"


@settings(max_examples=300, deadline=None)
@given(
    forged=st.lists(
        st.tuples(st.integers(1, 40), st.integers(0, 2**64 - 1),
                  st.integers(-(2**63), 2**63 - 1)),  # (after real block k, seq, t0)
        max_size=12,
    ),
)  # fmt: skip
def test_forged_blocks_never_move_a_channel_whatever_their_header(forged):
    """Any sequence number (uint64) and t0 (int64) put among real blocks: nothing raises, every
    kept number fits int64, a forged block admitted at all ends within ``max_ahead`` of its
    receive time or one block beyond the lead of the block before it, and when none was
    admitted the real blocks are admitted exactly as without them."""
    real = [(block(s, t0=NOW + s * STEP), NOW + (s + 1) * STEP) for s in range(40)]
    clean = ChannelHealth(fs_hz=1000.0)
    for b, r in real:
        clean.accept(b, r)
    h = ChannelHealth(fs_hz=1000.0)
    admitted = 0
    for k in range(40):
        h.accept(*real[k])
        for s, t in ((s, t) for kk, s, t in forged if kk == k + 1):
            lead = h.last_lead_ns
            got = h.accept(block(s, t0=t), real[k][1])
            if got.block is not None:
                admitted += 1
                assert got.block.t_end_ns - real[k][1] <= max(60 * 10**9, lead + STEP)
    if admitted == 0:
        assert _state(h) == _state(clean)
    for v in h.counters().values():
        assert not isinstance(v, int) or -(2**63) <= v < 2**63


def test_a_sender_faster_than_real_time_runs_ahead_one_block_at_a_time():
    """``simulate --publish --speed max``: a 10-minute scene received within a second is
    plausible block by block; a jump of 61 s beyond the lead it reached is not."""
    h = ChannelHealth(fs_hz=1000.0)
    for s in range(6000):
        got = h.accept(block(s, t0=NOW + s * STEP), recv_ns=NOW + s * 100_000)
        assert got.verdict in ("first", "next"), (s, got)
    assert h.last_lead_ns > 590 * 10**9
    recv = NOW + 6000 * 100_000
    assert h.accept(block(6610, t0=NOW + 6610 * STEP), recv).implausible == "t0_ahead"
    assert h.accept(block(6610, t0=NOW + 6000 * STEP), recv).implausible == "seq_ahead"
    assert h.accept(block(6000, t0=NOW + 6000 * STEP), recv).verdict == "next"


def test_a_poisoned_checkpoint_position_is_forgotten_and_the_counters_kept():
    """A checkpoint written before issue 26 after a forged seq 2^63: restored, the channel would
    drop every real block as a replay; its position is forgotten instead."""
    h = _history()
    saved = h.counters() | {"last_seq": 2**63, "missing_blocks": 2**63 - 11}
    again = ChannelHealth(fs_hz=1000.0)
    again.restore_counters(saved)
    assert again.drop_implausible_position()
    assert (again.last_seq, again.last_t0_ns, again.missing_blocks) == (None, None, 2**63 - 11)
    assert again.accept(block(10, t0=NOW), recv_ns=NOW + STEP).verdict == "first"
    fine = ChannelHealth()
    fine.restore_counters(h.counters())
    assert not fine.drop_implausible_position() and fine.last_seq == 9
