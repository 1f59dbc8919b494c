"""Channel health: sequence gaps, repeats, lag and staleness."""

from __future__ import annotations

import numpy as np

from ingest.wire import Unit, decode_block, encode_block
from service.worker.health import ChannelHealth, MillHealth


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
    from service.worker.health import PerMinute

    meter = PerMinute()
    s = 1_000_000_000
    assert meter.rate(0, 0) == 0.0
    assert meter.rate(30 * s, 3) == 3.0  # less than a minute seen: counted over a minute
    assert meter.rate(60 * s, 6) == 6.0
    assert meter.rate(120 * s, 6) == 0.0  # nothing new in the last minute


def test_latency_reservoir_reports_quantiles_of_the_kept_blocks():
    from types import SimpleNamespace

    from service.worker.health import LatencyReservoir

    r = LatencyReservoir(size=4)
    assert r.quantiles()["blocks"] == 0
    r.add_batch(10_000_000_000, [SimpleNamespace(recv_ns=t * 1_000_000_000) for t in range(10)])
    q = r.quantiles()
    assert q["blocks"] == 4 and q["max_s"] == 4.0  # only the newest four are kept: 4, 3, 2, 1 s
