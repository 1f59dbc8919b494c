"""How long the OPC UA server takes to make a condition object and to update it.

    PYTHONPATH=. .venv/bin/python tests/bench/bench_opcua_conditions.py [--alarms 40]

An asyncua server in process (no client) with the address space of one mill of the test
settings; ``--alarms`` start-peak alarms are raised (each a new ExclusiveLevelAlarmType
condition with its ShelvingState and ConfirmedState) and then acknowledged (an update: its
children written, its event sent). The alarm rows are made here, as the alarm board would hand
them over (this measures the OPC UA side only). The first condition of a type is made by
asyncua's ``instantiate`` and recorded; the others from that blueprint
(:meth:`millwatch.opcua.conditions.Conditions._instantiate`).
"""

from __future__ import annotations

import argparse
import asyncio
import logging
import statistics
import tempfile
import time
from pathlib import Path

from asyncua import Server, ua

from millwatch.alarms.lifecycle import Alarm, AlarmState
from millwatch.alarms.rules import Severity
from millwatch.opcua.address_space import (
    NAMESPACE_URI,
    MillNodes,
    mill_type,
    root_folder,
    site_folder,
)
from millwatch.opcua.conditions import Conditions
from tests.service.conftest import _settings


def _row(config_id: str, i: int, acked: bool) -> Alarm:
    return Alarm(
        f"a{i}", config_id, "start_peak", "", "start_peak_pct", "%", Severity.ALARM,
        AlarmState.ACKNOWLEDGED if acked else AlarmState.RAISED, 1, 2 if acked else 1,
        500.0, 348.0, "Start peak 500 % (alarm > 348 %)", seq=2 if acked else 1,
        acked_ns=2 if acked else None, acked_by="operator" if acked else None,
    )  # fmt: skip


async def run(alarms: int) -> tuple[list[float], list[float]]:
    server = Server()
    await server.init()
    ns = await server.register_namespace(NAMESPACE_URI)
    root = await root_folder(server, ns)
    await mill_type(server, ns)
    config = next(iter(_settings(Path(tempfile.mkdtemp()), 7447).load_mills().values()))
    site = await site_folder(server, root, config.site, ns)
    mill = await MillNodes.create(server, ns, site, config)
    notifiers = (mill.node.nodeid, site.nodeid, root.nodeid, ua.NodeId(ua.ObjectIds.Server))
    conditions = await Conditions.create(server, {config.id: mill}, {config.id: notifiers})
    create, update = [], []
    for i in range(alarms):
        t0 = time.perf_counter()
        await conditions.emit(_row(config.id, i, acked=False))
        create.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        await conditions.emit(_row(config.id, i, acked=True))
        update.append(time.perf_counter() - t0)
    return create, update


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--alarms", type=int, default=40)
    args = p.parse_args()
    logging.disable(logging.WARNING)  # asyncua's instantiate warns about attributes it skips
    create, update = asyncio.run(run(args.alarms))

    def ms(xs: list[float]) -> str:
        return f"median {statistics.median(xs) * 1e3:.1f} ms, max {max(xs) * 1e3:.1f} ms"

    print(f"first condition (asyncua instantiate, recorded): {create[0] * 1e3:.0f} ms")
    print(f"later conditions (from the blueprint): {ms(create[1:])}")
    print(f"updates (children written, event sent): {ms(update)}")


if __name__ == "__main__":
    main()
