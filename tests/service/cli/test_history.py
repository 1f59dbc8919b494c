"""``millwatch history build`` end to end as subprocesses: two simulated months of one mill
written quickly, then its monthly report and the fleet report read from that store say
"simulated" and show both months; mistakes are one line (exit status 2)."""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import pytest
from pypdf import PdfReader

MILLS = Path(__file__).resolve().parents[3] / "deploy" / "mills"
MILL = MILLS / "sag-5200-lrs.toml"
DUAL = MILLS / "ball-dual-lrs.toml"


def millwatch(*args: str | Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "millwatch.cli", *map(str, args)],
                          capture_output=True, text=True, timeout=300, check=False)  # fmt: skip


@pytest.fixture(scope="module")
def built(
    tmp_path_factory: pytest.TempPathFactory,
) -> tuple[Path, subprocess.CompletedProcess[str], float]:
    store = tmp_path_factory.mktemp("history") / "h.db"
    t = time.perf_counter()
    done = millwatch("history", "build", "--mills", MILL, DUAL, "--months", "2", "--last",
                     "2024-01", "--store", store, "--run-min", "1")  # fmt: skip
    return store, done, time.perf_counter() - t


def test_two_months_are_built_quickly_with_a_progress_bar(built):
    store, done, secs = built
    assert done.returncode == 0, done.stderr
    assert secs < 180  # per mill one 1-min cycle analysed, two months tiled
    assert "[" + "#" * 30 + "] 6/6" in done.stderr  # the bar: per mill 1 cycle + 2 months
    assert "2 SIMULATED months (2023-12 to 2024-01)" in done.stdout
    assert store.is_file()


def test_the_report_from_the_store_is_marked_simulated_and_has_the_history(built, tmp_path):
    store, _, _ = built
    done = millwatch("report", "--store", store, "--mill", "sag-5200-lrs", "--month",
                     "2024-01", "--format", "html", "--out", tmp_path)  # fmt: skip
    assert done.returncode == 0, done.stderr
    html = (tmp_path / "sag-5200-lrs" / "2024-01.html").read_text(encoding="utf-8")
    html = html.replace("<wbr>", "").replace("<span class='nw'>", "").replace("</span>", "")
    assert "SIMULATED DATA" in html
    assert "What changed since last month (2023-12)" in html
    # the monitored time reads the same on page 1 and in the trend table (one formatting)
    assert "Monitoring covered 31 days of the month." in html
    trend = html[html.index("t-trend_monthly") :]
    assert "<td class='nw'>2024-01</td><td class='nw'>31</td>" in trend.replace(
        "class='l nw'", "class='nw'"
    )
    fleet = millwatch("report", "--store", store, "--fleet", "rustenburg", "--month",
                      "2024-01", "--format", "html", "--out", tmp_path)  # fmt: skip
    assert fleet.returncode == 0, fleet.stderr
    page = (tmp_path / "rustenburg-fleet" / "2024-01.html").read_text(encoding="utf-8")
    page = page.replace("<wbr>", "").replace("<span class='nw'>", "").replace("</span>", "")
    assert "SIMULATED DATA" in page and "2023-12" in page and "in 2024-01" in page


def test_a_dual_drive_mills_summary_fits_page_one(built, tmp_path):
    store, _, _ = built
    done = millwatch("report", "--store", store, "--mill", "ball-dual-lrs", "--month",
                     "2024-01", "--format", "pdf", "--out", tmp_path)  # fmt: skip
    assert done.returncode == 0, done.stderr
    pages = PdfReader(tmp_path / "ball-dual-lrs" / "2024-01.pdf").pages
    first, second = (" ".join(pages[i].extract_text().split()) for i in (0, 1))
    assert "Summary" in first and "What changed since last month" in first
    assert "pinion_combined_nbs" in first  # all six components on page 1 …
    second_body = second.split("2024-01", 1)[1]  # (after the running header)
    assert second_body.lstrip().startswith("Remaining life and cumulative damage")  # … and no more


def test_an_existing_store_is_never_added_to(built):
    store, _, _ = built
    done = millwatch("history", "build", "--mills", MILL, "--months", "1", "--store", store)
    assert done.returncode == 2
    assert done.stderr.strip().splitlines()[-1] == (
        f"millwatch: error: store file {store} exists: choose a new path or give --replace "
        f"to delete it"
    )


def test_help_teaches_the_command():
    done = millwatch("history", "build", "--help")
    assert done.returncode == 0
    for words in ("--mills", "--months", "--store", "simulated", "millwatch report --store"):
        assert words in done.stdout


def test_a_built_history_shows_each_components_cycles_and_sn_curve(built, tmp_path):
    """The tiled months carry the analysed cycle's rainflow matrices: the report draws each
    component's range-mean matrix and S-N figure in HTML and PDF, none says "no cycles"."""
    store, _, _ = built
    done = millwatch("report", "--store", store, "--mill", "sag-5200-lrs", "--month",
                     "2024-01", "--format", "html,pdf", "--out", tmp_path)  # fmt: skip
    assert done.returncode == 0, done.stderr
    html = (tmp_path / "sag-5200-lrs" / "2024-01.html").read_text(encoding="utf-8")
    for comp in ("pinion_combined", "pinion_torsion", "motor_torsion"):
        assert f"<figure id='f-spectrum_{comp}'>" in html
    assert "no cycles counted" not in html
    pdf = PdfReader(tmp_path / "sag-5200-lrs" / "2024-01.pdf")
    text = " ".join(" ".join(p.extract_text().split()) for p in pdf.pages)
    assert "Rainflow cycles and S-N curves" in text and "no cycles counted" not in text
    assert sum(len(p.images) for p in pdf.pages) == html.count("<figure")
