"""tools/bench_ethercat.py: the master brings the emulated drives up and runs its exchange
(never its figures' values: a benchmark's timings are not a test's business), and what it
cannot run is one line, not a traceback."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def bench():
    path = ROOT / "tools" / "bench_ethercat.py"
    spec = importlib.util.spec_from_file_location("bench_ethercat_tool", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_the_drives_come_up_in_csp_and_the_exchange_runs(bench) -> None:
    """As root (CI): the drive group is built before the bus opens (its kernels warmed while
    no process data is due: after, that gap outlasted the slaves' 100 ms SM watchdog and
    set_mode timed out with the drives out of OP)."""
    from support.rootnet import require_root

    require_root("a veth pair")
    res = bench.run(1.0, 1000.0, ROOT / "configs" / "er3a.yaml")
    assert res["slaves"] == 6
    assert res["cycles"] > 0 and res["rtt_median_us"] > 0.0


def test_what_it_cannot_run_is_one_line(bench, monkeypatch, capsys) -> None:
    monkeypatch.setattr(bench.os, "geteuid", lambda: 0)  # past the root check: the config first
    monkeypatch.setattr(sys, "argv", ["bench_ethercat.py", "--config", "/nonexistent.yaml"])
    assert bench.main() == 1
    err = capsys.readouterr().err
    assert err == "bench_ethercat: /nonexistent.yaml: config file not found\n"
