"""The deployment config (configs/er3a_service.yaml) as `hofto-hw run` runs it: nothing
scripted, until stopped (SIGTERM: category 1, exit 0), the compiled tick required
(``loop.acceleration``: a missing compiled path refuses in one line, ``preferred`` too: the
tick has no other path); `run --help` states its defaults."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[3]
SERVICE = ROOT / "configs" / "er3a_service.yaml"


def _env(**extra: str) -> dict[str, str]:
    return {**os.environ, "PYTHONPATH": str(ROOT), **extra}


def _service_on_sim(folder: Path) -> Path:
    data = yaml.safe_load(SERVICE.read_text())
    data["robot"]["urdf"] = str((SERVICE.parent / data["robot"]["urdf"]).resolve())
    data["bus"] = {**data["bus"], "transport": "sim"}
    data["run"]["log_dir"] = str(folder / "logs")
    path = folder / "robot.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def _run(*args: str, **env: str) -> subprocess.Popen:
    cmd = [sys.executable, "-m", "hofto_hw.cli", "run", *args]
    return subprocess.Popen(
        cmd, cwd=ROOT, env=_env(**env), stderr=subprocess.PIPE, stdout=subprocess.PIPE, text=True
    )


def test_service_config_scripts_nothing_and_runs_until_sigterm(tmp_path: Path) -> None:
    data = yaml.safe_load(SERVICE.read_text())
    assert data["run"]["duration"] is None and data["loop"]["acceleration"] == "required"
    assert data["run"]["path"] is None and data["run"]["collision"] is None
    assert data["run"]["drag"] is None and data["bus"]["transport"] == "ethercat"
    summary = tmp_path / "summary.json"
    proc = _run(
        "--config",
        str(_service_on_sim(tmp_path)),
        "--clock",
        "sim",
        "--no-log",
        "--summary-json",
        str(summary),
    )
    try:
        assert proc.stderr is not None
        seen = []
        for line in proc.stderr:  # wait for the state: the loop runs (sim clock: no end)
            seen.append(line)
            if line.startswith("hofto-hw run: running"):
                break
        assert "tick: compiled" in seen[-1], seen
        proc.send_signal(signal.SIGTERM)
        stdout, stderr = proc.communicate(timeout=300)
    finally:
        proc.kill()
    assert proc.returncode == 0, stderr
    s = json.loads(summary.read_text())
    assert [e["kind"] for e in s["events"]] == ["stop_request"]
    assert s["events"][0]["category"] == 1 and s["observers"]["hofto"] is None
    assert s["bus"] == "sim (simulated arm)" and s["acceleration"]["compiled"] is True
    assert s["realtime"] == "real-time not used with the sim clock"
    assert "real-time" not in stderr and "realtime" not in stderr


def test_the_demo_config_runs_its_loop_as_the_service_does() -> None:
    """configs/er3a.yaml (the README's job, and what tools/bench_tick.py and bench_loop.py
    measure by default) sets up its loop as the service's config does: rate, real-time mode,
    priority, CPU placement and wake-up latency limit; only ``acceleration`` differs (the
    service requires the compiled tick)."""
    keys = ("rate_hz", "realtime", "priority", "cpus", "cpu_latency_us")
    demo = yaml.safe_load((ROOT / "configs" / "er3a.yaml").read_text())["loop"]
    service = yaml.safe_load(SERVICE.read_text())["loop"]
    assert {k: demo.get(k) for k in keys} == {k: service.get(k) for k in keys}
    assert service["cpus"] == "last"


def test_required_acceleration_refuses_without_the_native_library(tmp_path: Path) -> None:
    proc = _run(
        "--config",
        str(_service_on_sim(tmp_path)),
        "--clock",
        "sim",
        "--no-log",
        HOFTO_HW_NO_NATIVE="1",
    )
    _, stderr = proc.communicate(timeout=300)
    assert proc.returncode == 2
    lines = [ln for ln in stderr.splitlines() if "loop.acceleration" in ln]
    assert len(lines) == 1 and "HOFTO_HW_NO_NATIVE" in lines[0], stderr
    assert "robot.yaml" in lines[0] and "Traceback" not in stderr


def test_preferred_acceleration_refuses_without_the_native_library_too(tmp_path: Path) -> None:
    """The tick has one path, the compiled one: no Python reference to fall back on."""
    proc = _run(
        "--config",
        "er3a",
        "--clock",
        "sim",
        "--duration",
        "0.3",
        "--no-log",
        "--no-collision",
        HOFTO_HW_NO_NATIVE="1",
    )
    _, stderr = proc.communicate(timeout=300)
    assert proc.returncode == 2, stderr
    lines = [ln for ln in stderr.splitlines() if "loop.acceleration: preferred" in ln]
    assert len(lines) == 1 and "HOFTO_HW_NO_NATIVE" in lines[0], stderr
    assert "Traceback" not in stderr


def test_run_help_states_the_defaults() -> None:
    res = subprocess.run(
        [sys.executable, "-m", "hofto_hw.cli", "run", "--help"],
        cwd=ROOT,
        env=_env(COLUMNS="200"),
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert res.returncode == 0
    text = " ".join(res.stdout.split())
    assert "real unless set" in text and "er3a: 12 s" in text and "until SIGTERM" in text
    assert "--config PATH|ROBOT" in text and "(default: er3a)" in text
