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
    cmd += ["--summary-json", str(summary), "--plot", str(folder / "run.png")]
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert f"plot: {folder / 'run.png'}" in proc.stdout
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


# ------------------------------------------------------------------ the pictures of a run

PNG = b"\x89PNG\r\n\x1a\n"


def test_run_plot_draws_every_panel(run_log) -> None:
    """`run --plot` wrote the figure; its panels: joints, per-joint torque against both
    thresholds with the collision marked, the stop, drag (none in 3.8 s), loop timing."""
    from hofto_hw.replay.run_plot import run_figure, titles

    path, summary = run_log
    assert (path.parent / "run.png").read_bytes()[:8] == PNG
    fig = run_figure(read_flight_log(path))
    names = titles(fig)
    assert names[0] == "joint positions"
    torque = [t for t in names if t.endswith("estimated external torque vs thresholds")]
    assert len(torque) == 6
    stop = next(t for t in names if t.startswith("stop: "))
    col = next(e for e in summary["events"] if e["kind"] == "collision")
    assert stop.startswith("stop: collision (category 1)")
    assert f"at rest after {col['stopping_time_ms']:.0f} ms" in stop  # the summary's figure
    assert "drag: none in this run" in names
    assert any(t.startswith("loop timing: compute median") for t in names)
    ax = next(a for a in fig.axes if a.get_title() == torque[1])
    labels = {line.get_label() for line in ax.get_lines()}
    assert {"hofto estimate", "contact threshold", "collision threshold"} <= labels
    thr = next(line for line in ax.get_lines() if line.get_label() == "collision threshold")
    assert np.nanmin(thr.get_ydata()) > 0.0  # a threshold was computed on judged ticks


def test_log_plot_writes_next_to_the_log_and_never_overwrites(run_log, tmp_path, capsys):
    path = run_log[0]
    out = tmp_path / "fig.png"
    assert main(["log", "plot", str(path), "-o", str(out)]) == 0
    assert out.read_bytes()[:8] == PNG
    copy = tmp_path / "copy.mcap"
    copy.write_bytes(path.read_bytes())
    assert main(["log", "plot", str(copy)]) == 0
    assert (tmp_path / "copy.png").read_bytes()[:8] == PNG
    assert main(["log", "plot", str(copy)]) == 2  # the default exists: name it with -o
    assert "exists" in capsys.readouterr().err
    assert main(["log", "plot", str(copy), "-o", str(copy)]) == 2
    assert copy.read_bytes() == path.read_bytes()


def test_drag_panel_shows_the_tool_speed_in_drag_mode(run_log) -> None:
    from hofto_hw.control.joint_motion import DRAG
    from hofto_hw.replay.run_plot import run_figure, titles

    log = read_flight_log(run_log[0])
    assert log.mode is not None
    mode = log.mode.copy()
    mode[1000:1500] = DRAG  # the demo path, moving: a nonzero tool speed
    names = titles(run_figure(dataclasses.replace(log, mode=mode)))
    drag = next(t for t in names if t.startswith("drag: "))
    assert drag.startswith("drag: tool speed, max") and "over 0.50 s in drag mode" in drag
    assert float(drag.split("max ")[1].split(" mm/s")[0]) > 10.0


def test_replay_plot_writes_recorded_vs_replayed_per_joint(run_log, tmp_path, capsys):
    from hofto_hw.replay.run_plot import replay_figure, titles

    out = tmp_path / "replay.png"
    assert main(["replay", str(run_log[0]), "--plot", str(out)]) == 0
    assert f"plot: {out}" in capsys.readouterr().out
    assert out.read_bytes()[:8] == PNG
    log = read_flight_log(run_log[0])
    r = reproduce(log)
    names = titles(replay_figure(log, r.replayed, r.detector, r.replayed_tick))
    assert len(names) == 6
    assert all("hofto estimate, recorded vs replayed" in t for t in names)


def test_replay_plot_refuses_to_overwrite_the_log(run_log, tmp_path, capsys) -> None:
    copy = tmp_path / "copy.mcap"
    copy.write_bytes(run_log[0].read_bytes())
    assert main(["replay", str(copy), "--plot", str(copy)]) == 2
    err = capsys.readouterr().err
    assert "refusing to overwrite" in err and len(err.strip().splitlines()) == 1
    assert copy.read_bytes() == run_log[0].read_bytes()


def test_run_plot_without_a_log_is_refused_before_the_run(tmp_path, capsys) -> None:
    assert main(["run", "--no-log", "--plot", str(tmp_path / "x.png")]) == 2
    assert "drop --no-log" in capsys.readouterr().err
    assert not (tmp_path / "x.png").exists()


def test_the_log_carries_the_monitor_s_thresholds_as_replay_computes_them(run_log) -> None:
    """/safety/thresholds (computed by the writer process batch by batch while the run went)
    equals the thresholds re-computed from the whole log, on every judged tick."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    from hofto_hw.recording import schemas as s
    from hofto_hw.replay.run_plot import _thresholds

    log = read_flight_log(run_log[0])
    observer, thr, levels = _thresholds(log)
    assert observer == "hofto" and levels == ("contact", "collision") and thr is not None
    with run_log[0].open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        msgs = [
            (m.sequence, msg)
            for _s, _c, m, msg in reader.iter_decoded_messages(topics=[s.THRESHOLDS_TOPIC])
        ]
    assert log.monitored is not None
    judged = np.flatnonzero(log.monitored)
    assert [k for k, _ in msgs] == list(log.ticks[judged])
    assert all(msg.observer == "hofto" for _, msg in msgs)
    logged = np.array([[msg.contact, msg.collision] for _, msg in msgs])
    assert np.array_equal(logged, thr[judged])
    assert (logged[:, 1] > logged[:, 0]).all()  # collision above contact everywhere
