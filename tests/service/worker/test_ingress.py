"""The ingress gate refuses oversize payloads and keys of no configured channel before the queue
and the archive, counted per key prefix and logged once per prefix (issue 26)."""

from __future__ import annotations

import logging
import threading
from pathlib import Path

from millwatch.ingest.keys import ChannelRoutes, channel_key
from millwatch.ingest.mill_files import load_mill_config
from millwatch.worker.admission import IngressGate

MILL = Path(__file__).resolve().parents[3] / "deploy" / "mills" / "sag-5200-lrs.toml"
CONFIG = load_mill_config(MILL)
PREFIX = f"millwatch/v1/{CONFIG.site}/{CONFIG.id}"


def _gate(max_bytes: int = 4096) -> IngressGate:
    return IngressGate(ChannelRoutes([CONFIG]).route, max_bytes)


def test_configured_keys_up_to_the_size_limit_pass():
    gate = _gate()
    for channel in CONFIG.channels.values():
        assert gate.admit(channel_key(CONFIG.site, CONFIG.id, channel.key), b"x" * 4096)
    assert gate.refused == 0


def test_a_flood_of_made_up_keys_is_one_count_and_one_log_line(caplog):
    gate = _gate()
    with caplog.at_level(logging.WARNING, logger="millwatch.worker.admission"):
        assert not any(gate.admit(f"{PREFIX}/junk{k}", b"MWBK") for k in range(5000))
    assert gate.unknown == {PREFIX: 5000} and gate.oversize == {}
    assert len(caplog.records) == 1 and PREFIX in caplog.records[0].getMessage()


def test_an_oversize_block_is_refused_even_on_a_configured_key(caplog):
    gate = _gate()
    key = channel_key(CONFIG.site, CONFIG.id, next(iter(CONFIG.channels.values())).key)
    with caplog.at_level(logging.WARNING, logger="millwatch.worker.admission"):
        assert not gate.admit(key, bytes(40 * 2**20))  # the 40 MB block of issue 26
        assert not gate.admit(key, bytes(4097))
    assert gate.oversize == {PREFIX: 2} and gate.refused == 2
    assert len(caplog.records) == 1 and "41943040 bytes" in caplog.records[0].getMessage()


def test_counts_are_exact_from_many_threads():
    gate = _gate()

    def flood(n: int) -> None:
        for k in range(2000):
            gate.admit(f"{PREFIX}/t{n}-{k}", b"")

    threads = [threading.Thread(target=flood, args=(n,)) for n in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=30)
    assert gate.unknown == {PREFIX: 8000}
