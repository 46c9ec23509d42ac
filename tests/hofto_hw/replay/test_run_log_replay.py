"""`hofto-hw replay` on a log written by the real `hofto-hw run` process: the two-level
collision monitor (safety.collision, CollisionLevels) rebuilt from the attached config, fed
the recomputed estimates of every loop observer, decides in the same tick on the same joint."""

from __future__ import annotations

import dataclasses
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from hofto_hw.cli import main
from hofto_hw.replay.flight_log import read_flight_log
from hofto_hw.replay.reproduce import reproduce

ROOT = Path(__file__).resolve().parents[3]
CONFIG = ROOT / "configs" / "er3a.yaml"  # scripted collision on joint index 1 at t = 3.0 s,
# scripted reset at 3.5 s


@pytest.fixture(scope="module")
def run_log(tmp_path_factory) -> tuple[Path, dict]:
    folder = tmp_path_factory.mktemp("runlog")
    summary = folder / "summary.json"
    cmd = [sys.executable, "-m", "hofto_hw.cli", "run", "--config", str(CONFIG)]
    cmd += ["--clock", "sim", "--duration", "3.8", "--log-dir", str(folder)]
    cmd += ["--summary-json", str(summary)]
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    (log,) = folder.glob("*.mcap")
    return log, json.loads(summary.read_text())


def test_replay_reproduces_the_runs_collision_tick_and_joint(run_log, capsys) -> None:
    path, summary = run_log
    col = [e for e in summary["events"] if e["kind"] == "collision"]
    assert col, "the scripted collision was not detected by the run"
    assert main(["replay", str(path), "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["match"] is True and d["detector"] == "hofto"
    assert d["recorded"]["tick"] == d["replayed"]["tick"] == col[0]["tick"]
    assert d["recorded"]["joint"] == col[0]["joint"] == 1 and 1 in d["replayed"]["joints"]


def test_run_log_records_what_the_monitor_needs(run_log) -> None:
    log = read_flight_log(run_log[0])
    assert log.monitored is not None and log.qdd_cmd is not None
    assert log.qdd_cmd.shape == log.q.shape and np.isfinite(log.qdd_cmd).all()
    assert log.monitored.any() and not log.monitored.all()  # judged until the stop took power
    assert np.abs(log.qdd_cmd).max() > 0.0  # the demo path accelerates


def test_a_doctored_log_is_a_mismatch(run_log) -> None:
    log = read_flight_log(run_log[0])
    good = reproduce(log)
    assert good.match
    shifted = [dataclasses.replace(e, tick=e.tick + 1) for e in log.events]
    assert not reproduce(dataclasses.replace(log, events=shifted)).match
    # the recorded judged-ticks flag matters: with it cleared the replay never decides
    blind = dataclasses.replace(log, monitored=np.zeros_like(log.monitored))
    r = reproduce(blind)
    assert r.replayed_tick is None and not r.match


def test_replayed_estimates_follow_the_runs_reset(run_log) -> None:
    """After the start-up transient the replayed estimates are the loop's, also after the
    reset (the loop resets its observers in the reset's tick; replay reads the event)."""
    from hofto_hw.observers.registry import make_observer
    from hofto_hw.replay import reproduce as rep
    from hofto_hw.runtime.compose import loop_observer_table

    log = read_flight_log(run_log[0])
    resets = [e.tick for e in log.events if e.kind_name == rep.RESET_KIND]
    assert resets, "the scripted reset did not happen"
    setup = rep.run_setup(log)
    dt = rep.loop_dt(log, float(setup.config.loop.rate_hz))
    table = loop_observer_table(setup.config)
    after = int(np.searchsorted(log.ticks, resets[0]))
    for name in log.observers:
        obs = make_observer(table[name], rep.loop_model(setup), backend=rep.recorded_backend(log))
        diff = np.abs(rep._run_with_dt(obs, log, dt) - log.tau_ext[name]).max(axis=1)
        assert diff[200:].max() < 1e-9, (name, float(diff[200:].max()))
        assert diff[after:].max() < 1e-9
