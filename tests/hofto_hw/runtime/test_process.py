"""`hofto-hw run` as a process: SIGTERM -> category 1 stop -> drives off -> exit 0;
loop.realtime required/preferred as an unprivileged user; the tick allocates nothing."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest
import yaml
from support.alloc import tick_memory

from hofto_hw.config.models import SystemConfig
from hofto_hw.control.joint_motion import MOVE
from hofto_hw.runtime.compose import build
from tests.hofto_hw.runtime.conftest import CONFIG

ROOT = Path(__file__).resolve().parents[3]


def _env() -> dict[str, str]:
    return {**os.environ, "PYTHONPATH": str(ROOT)}


def test_sigterm_stops_category_1_and_exits_0(tmp_path: Path) -> None:
    out = tmp_path / "summary.json"
    cmd = [sys.executable, "-m", "hofto_hw.cli", "run", "--config", str(CONFIG)]
    cmd += ["--clock", "real", "--duration", "120", "--no-collision", "--no-log"]
    cmd += ["--summary-json", str(out)]
    proc = subprocess.Popen(
        cmd, cwd=ROOT, env=_env(), stderr=subprocess.PIPE, stdout=subprocess.PIPE, text=True
    )
    try:
        assert proc.stderr is not None
        for line in proc.stderr:  # wait for the state, not for a time
            if line.startswith("hofto-hw run: running"):
                break
        proc.send_signal(signal.SIGTERM)
        stdout, stderr = proc.communicate(timeout=120)
    finally:
        proc.kill()
    assert proc.returncode == 0, stderr
    s = json.loads(out.read_text())
    ev = [e for e in s["events"] if e["kind"] == "stop_request"]
    assert len(ev) == 1 and ev[0]["category"] == 1
    # on a loaded machine missed deadlines may have latched too (also category 1)
    assert "stop_request" in s["latched"]
    assert "stop request" in stdout


def _config_file(folder: Path, realtime: str) -> Path:
    data = yaml.safe_load(CONFIG.read_text())
    data["robot"]["urdf"] = str((CONFIG.parent / data["robot"]["urdf"]).resolve())
    data["loop"]["realtime"] = realtime
    path = folder / f"rt-{realtime}.yaml"
    path.write_text(yaml.safe_dump(data))
    path.chmod(0o644)
    return path


def _as_nobody(args: list[str]) -> subprocess.CompletedProcess[str]:
    # as a plain user: no capabilities, default limits (no real-time priority, 64 KiB locked)
    cmd = ["prlimit", "--rtprio=0", "--memlock=65536", "setpriv", "--reuid=65534"]
    cmd += ["--regid=65534", "--clear-groups", "--inh-caps=-all", sys.executable]
    cmd += ["-m", "hofto_hw.cli", *args]
    return subprocess.run(cmd, cwd="/", env=_env(), capture_output=True, text=True, timeout=300)


@pytest.fixture
def public_dir() -> Path:
    if os.geteuid() != 0 or not shutil.which("setpriv") or not shutil.which("prlimit"):
        if os.environ.get("CI"):
            pytest.fail("CI must run this test as root with setpriv and prlimit (util-linux)")
        pytest.skip("needs root to switch to an unprivileged user (setpriv, prlimit)")
    d = Path(tempfile.mkdtemp(prefix="hofto-rt-"))
    d.chmod(0o755)
    yield d
    shutil.rmtree(d)


def test_realtime_required_refuses_unprivileged_naming_the_capability(public_dir: Path) -> None:
    cfg = _config_file(public_dir, "required")
    r = _as_nobody(["run", "--config", str(cfg), "--clock", "sim", "--duration", "0.1", "--no-log"])
    assert r.returncode == 2, r.stderr
    assert "loop.realtime: required" in r.stderr
    assert "CAP_SYS_NICE" in r.stderr and "CAP_IPC_LOCK" in r.stderr
    assert "Traceback" not in r.stderr


def test_realtime_required_on_the_real_clock_names_the_cpu_latency_device(
    public_dir: Path,
) -> None:
    cfg = _config_file(public_dir, "required")
    args = ["run", "--config", str(cfg), "--clock", "real", "--duration", "0.1", "--no-log"]
    r = _as_nobody(args)
    assert r.returncode == 2, r.stderr
    assert "write access to /dev/cpu_dma_latency" in r.stderr and "Traceback" not in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1


def test_realtime_preferred_runs_unprivileged_with_one_warning(public_dir: Path) -> None:
    cfg = _config_file(public_dir, "preferred")
    args = ["run", "--config", str(cfg), "--clock", "real", "--duration", "0.2", "--no-log"]
    r = _as_nobody(args)
    assert r.returncode == 0, r.stderr
    assert r.stderr.count("warning: real-time setup incomplete") == 1
    assert "ran 200 ticks" in r.stdout


def test_sim_clock_run_unprivileged_says_nothing_about_real_time(public_dir: Path) -> None:
    """The sim clock never sleeps and runs at normal priority: nothing to set up or warn."""
    cfg = _config_file(public_dir, "preferred")
    r = _as_nobody(["run", "--config", str(cfg), "--clock", "sim", "--duration", "0.2", "--no-log"])
    assert r.returncode == 0, r.stderr
    assert "real-time" not in r.stderr and "realtime" not in r.stderr
    assert "ran 200 ticks" in r.stdout and "real-time not used with the sim clock" in r.stdout


def test_tick_allocates_nothing_after_warm_up(cfg: SystemConfig) -> None:
    system = build(cfg, clock="sim", contact=False)
    system.tick.mode_request = MOVE
    system.loop.run(max_ticks=1500)
    grown, peak = tick_memory(system)
    assert system.tick.stop.latched == 0
    # nothing kept per tick (3000 ticks x one (6,) array would be > 300 kB) and no large
    # temporaries: only scalars and the short-lived wrappers pinocchio returns
    assert grown < 4000
    assert peak < 16000
