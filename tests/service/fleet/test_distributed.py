"""``millwatch analyze --scheduler``: mills analysed on a Dask cluster (two worker processes on
127.0.0.1) give the report one process gives, byte for byte; a worker that dies is replaced and
its mill analysed again; errors name the scheduler's address, the mill and the file."""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import io
import json
import os
import socket
from pathlib import Path
from typing import Any

import pytest

distributed = pytest.importorskip("distributed")

from millwatch.cli.main import main  # noqa: E402
from millwatch.fleet.distributed import (  # noqa: E402
    WORKER_CONFIG,
    MillTask,
    analyze_mill,
    dask_client,
    plan_tasks,
    run_on_dask,
)
from millwatch.ingest.mill_files import load_mill_config  # noqa: E402

MILLS = Path(__file__).resolve().parents[3] / "deploy" / "mills"
SAG, ROD, BALL = (MILLS / f"{m}.toml" for m in ("sag-5200-lrs", "rod-1100-grid", "ball-dual-lrs"))


def _simulate(scene: str, mill: Path, out: Path) -> None:
    assert main(["simulate", "--scene", scene, "--mill", str(mill), "--duration", "40s",
                 "--out", str(out), "--no-progress", "--seed", "5"]) == 0  # fmt: skip


@pytest.fixture(scope="module")
def plant(tmp_path_factory) -> Path:
    """Three mills' recordings in one directory: the SAG mill's in files named after it (as
    ``simulate --out DIR`` writes them: read only by its task), the rod mill's and the ball
    mill's in files named after no mill (as a worker's archive, which holds all its mills:
    read by every task). The ball mill is not given to the analysis: its blocks are foreign."""
    d = tmp_path_factory.mktemp("plant")
    _simulate("start-lrs", SAG, d)
    _simulate("start-grid", ROD, d / "b.mcap")
    _simulate("start-lrs", BALL, d / "c.mcap")
    return d


@pytest.fixture(scope="module")
def cluster():
    """Two worker processes of one thread on 127.0.0.1 (no interface but loopback); a task
    whose worker dies is run again once, then given up (``allowed-failures``: 1)."""
    import dask

    with (
        dask.config.set({**WORKER_CONFIG, "distributed.scheduler.allowed-failures": 1}),
        distributed.LocalCluster(
            n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
            dashboard_address="127.0.0.1:0",
        ) as lc,
    ):  # fmt: skip
        yield lc


def _analyze(*args: str) -> bytes:
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        assert main(["analyze", *args, "--json", "--no-progress"]) == 0
    return buf.getvalue().encode()


def test_dask_gives_the_report_of_one_process_byte_for_byte(plant, cluster):
    given = [str(plant), "--mill", str(SAG), "--mill", str(ROD)]
    one = _analyze(*given, "--jobs", "1")
    on_dask = _analyze(*given, "--scheduler", cluster.scheduler_address)
    assert on_dask == one
    report = json.loads(one)
    assert [m["mill"] for m in report["mills"]] == ["sag-5200-lrs", "rod-1100-grid"]
    assert all(m["samples"] == 40_000 and len(m["starts"]) == 1 for m in report["mills"])
    # the ball mill's blocks, counted once; the rod mill's are not foreign to the SAG task
    (foreign,) = {m["reading"]["foreign_blocks"] for m in report["mills"]}
    assert foreign == len(load_mill_config(BALL).channels) * 40_000 // 100  # blocks of 100


def test_jobs_split_over_processes_give_the_report_of_one_process(plant):
    """``--jobs 2``: a job does not count the other job's given mills as foreign blocks
    (their files are named after no mill, so both jobs read them)."""
    given = [str(plant), "--mill", str(SAG), "--mill", str(ROD)]
    assert _analyze(*given, "--jobs", "2") == _analyze(*given, "--jobs", "1")


def test_a_group_of_mills_on_a_worker_gives_the_same_bytes(plant, cluster):
    """Three mills, shared files, two worker threads: two tasks, one of two mills."""
    given = [str(plant), "--mill", str(SAG), "--mill", str(ROD), "--mill", str(BALL)]
    assert _analyze(*given, "--scheduler", cluster.scheduler_address) == _analyze(*given)


def test_one_task_per_mill_reads_its_own_files_and_the_shared_ones(plant):
    files = sorted(plant.glob("*.mcap"))
    sag, rod = load_mill_config(SAG), load_mill_config(ROD)
    tasks = plan_tasks(files, [sag, rod])
    assert [t.mill for t in tasks] == ["sag-5200-lrs", "rod-1100-grid"]
    own = [p for p in files if p.name.startswith("sag-5200-lrs_")]
    shared = [plant / "b.mcap", plant / "c.mcap"]
    assert own and set(tasks[0].files) == {*own, *shared} and not tasks[0].uncounted
    assert tasks[1].files == tuple(shared) and tasks[1].uncounted == set(shared)
    assert tasks[0].others == (rod,) and tasks[1].others == (sag,)


def test_mills_sharing_files_are_grouped_one_task_per_worker_thread(plant):
    """A shared file is read whole by every task that reads it: with shared files, as many
    tasks as worker threads; with each mill's own files, one per mill whatever the threads."""
    ball, rod, sag = (load_mill_config(m) for m in (BALL, ROD, SAG))
    shared = [plant / "b.mcap", plant / "c.mcap"]
    grouped = plan_tasks(shared, [sag, rod, ball], shared_groups=2)
    assert [t.mill for t in grouped] == ["sag-5200-lrs, ball-dual-lrs", "rod-1100-grid"]
    assert grouped[1].others == (sag, ball) and grouped[1].uncounted == set(shared)
    own = sorted(plant.glob("sag-5200-lrs_*.mcap"))
    assert len(plan_tasks(own, [sag, rod, ball], shared_groups=2)) == 3


def test_a_local_cluster_started_for_the_run(plant):
    given = [str(plant / "b.mcap"), "--mill", str(ROD)]
    assert _analyze(*given, "--scheduler", "local:1") == _analyze(*given)


def test_local_workers_keep_the_system_allocator_s_trim_threshold():
    """Dask's MALLOC_TRIM_THRESHOLD_=65536 nearly doubled the analysis's CPU time (page faults
    of freed temporaries): the workers of ``local:N`` are started without it."""
    with dask_client("local:1") as client:
        env = client.run(os.environ.get, "MALLOC_TRIM_THRESHOLD_")
    assert list(env.values()) == [None]


def _die_once(task: MillTask, marker: str) -> dict[str, Any]:
    """A task whose first run kills its worker process (as the kernel's OOM killer would)."""
    if not os.path.exists(marker):
        Path(marker).touch()
        os._exit(9)
    return analyze_mill(task)


def _die_always(task: MillTask) -> dict[str, Any]:
    os._exit(9)


def test_a_worker_that_dies_mid_task_is_replaced_and_the_mill_analysed_again(
    plant, cluster, tmp_path, capsys
):
    tasks = plan_tasks([plant / "b.mcap"], [load_mill_config(ROD)])
    with dask_client(cluster.scheduler_address) as client:
        (expected,) = run_on_dask(tasks, client)
        dying = functools.partial(_die_once, marker=str(tmp_path / "died"))
        (again,) = run_on_dask(tasks, client, progress=True, analyze=dying)
    assert (tmp_path / "died").exists()
    assert json.dumps(again["reports"]) == json.dumps(expected["reports"])
    assert "1/1" in capsys.readouterr().err  # the progress bar counts mills


def test_a_mill_whose_workers_keep_dying_is_named(plant, cluster):
    tasks = plan_tasks([plant / "b.mcap"], [load_mill_config(ROD)])
    with (
        dask_client(cluster.scheduler_address) as client,
        pytest.raises(RuntimeError, match=r"mill\(s\) rod-1100-grid on Dask: every worker"),
    ):
        run_on_dask(tasks, client, analyze=_die_always)


def test_a_file_the_workers_cannot_see_is_named_with_the_mill(plant, cluster):
    (task,) = plan_tasks([Path("b.mcap")], [load_mill_config(ROD)])
    elsewhere = dataclasses.replace(task, cwd=plant / "not-shared")
    with dask_client(cluster.scheduler_address) as client, pytest.raises(ValueError) as err:
        run_on_dask([elsewhere], client)
    message = str(err.value)
    assert "mill(s) rod-1100-grid" in message and "not-shared/b.mcap" in message
    assert "not found on the Dask worker tcp://127.0.0.1:" in message


def test_an_unreachable_scheduler_is_named_with_its_address(capsys):
    with socket.socket() as s:  # a port on loopback where nothing listens
        s.bind(("127.0.0.1", 0))
        address = f"tcp://127.0.0.1:{s.getsockname()[1]}"
    refused = f"--scheduler {address}: no Dask scheduler answered within 2 s"
    with pytest.raises(ValueError, match=refused), dask_client(address, timeout_s=2):
        pass


def test_a_local_cluster_needs_a_worker():
    with (
        pytest.raises(ValueError, match="local:0: needs at least one worker"),
        dask_client("local:0"),
    ):
        pass
