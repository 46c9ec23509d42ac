"""``Robot.set_payload`` and ``hofto-hw payload set`` against a real ``hofto-hw run --clock
real --socket S`` on the simulated bus whose arm holds 2 kg the config does not know: the
estimates at rest show the load's weight until the payload is set, go to ~0 with the right
one, show the missing part with a wrong one; refused while moving and outside the rating;
shown by state() and status(); flight-log events with its values."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml
from support.control_service import ROOT, Service, socket_config, wait_for

from hofto_hw.client import Refused, Robot
from hofto_hw.config.loader import load_config
from hofto_hw.model.payload import Payload, apply_payload
from hofto_hw.runtime.compose import build_model

COM = [0.01, -0.02, 0.06]


def _config(tmp: Path) -> Path:
    path = socket_config(tmp)
    data = yaml.safe_load(path.read_text())
    data["safety"]["payload"] = {"mass": 0.0}
    data["run"]["simulated_payload"] = {"mass": 2.0, "com": COM}
    data["run"]["model_error"] = 0.0  # the load is what differs
    data["safety"].pop("collision")  # an unmodelled load is measured here, not stopped
    path.write_text(yaml.safe_dump(data))
    return path


def _weight(cfg, q: np.ndarray, mass: float) -> np.ndarray:
    """The observers' view of ``mass`` at COM the model lacks: -(g with it - g without)."""
    bare, loaded = build_model(cfg), build_model(cfg)
    apply_payload(loaded, Payload(mass, tuple(COM)))
    return bare.create_data().gravity(q) - loaded.create_data().gravity(q)


def _at_rest(robot: Robot) -> bool:
    s = robot.state()
    return s.mode == "hold" and float(np.abs(s.qd).max()) < 0.01


def _shows(robot: Robot, expected: np.ndarray, tol: float) -> bool:
    s = robot.state()
    return all(float(np.abs(v - expected).max()) < tol for v in s.tau_ext.values())


def test_set_payload_through_the_client_and_the_cli(tmp_path: Path) -> None:
    from hofto_hw.replay.flight_log import read_flight_log

    config = _config(tmp_path)
    cfg = load_config(config)
    svc = Service(tmp_path, "--hold", "--no-collision", config=config)
    try:
        with Robot.connect(socket=svc.sock) as robot:
            s = robot.state()
            assert s.payload is not None and s.payload.mass == 0.0
            wait_for(lambda: _at_rest(robot), "hold at rest")
            q0 = robot.state().q_cmd
            m = robot.move_joints(q0 + 0.2, speed=0.1, acceleration=0.1, wait=False)
            wait_for(lambda: robot.state().moving, "moving")
            with pytest.raises(Refused, match="changes at standstill"):
                robot.set_payload(2.0, COM)
            m.wait(timeout=120.0)
            wait_for(lambda: _at_rest(robot), "at rest after the move")
            with pytest.raises(Refused, match=r"within \[0, 3\] kg"):
                robot.set_payload(5.0, COM)
            with pytest.raises(Refused, match=r"com_max = 0\.15 m"):
                robot.set_payload(1.0, [0.0, 0.0, 0.5])
            assert robot.state().payload.mass == 0.0  # nothing taken

            q = robot.state().q
            load = _weight(cfg, q, 2.0)
            tol = 0.1 * float(np.abs(load).max())
            wait_for(lambda: _shows(robot, load, tol), "the estimates show the 2 kg")

            got = robot.set_payload(2.0, COM)
            assert got.mass == 2.0 and np.allclose(got.com, COM)
            s = robot.state()
            assert s.payload.mass == 2.0 and np.allclose(s.payload.com, COM)
            assert robot.status()["payload"] == {"mass": 2.0, "com": COM}
            wait_for(lambda: _shows(robot, np.zeros(6), tol), "estimates ~0")

            robot.release()  # motion and safety settings: one client at a time
            env = {**os.environ, "PYTHONPATH": str(ROOT)}
            cmd = [sys.executable, "-m", "hofto_hw.cli", "payload", "set", "0.5", "--com"]
            cmd += [str(v) for v in COM] + ["--socket", str(svc.sock)]
            out = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=120)
            assert out.returncode == 0, out.stderr
            assert out.stdout.startswith("payload 0.5 kg at com") and out.stderr == ""
            missing = load - _weight(cfg, q, 0.5)
            wait_for(lambda: _shows(robot, missing, tol), "the estimates show the missing 1.5 kg")
            assert robot.state().payload.mass == 0.5
        svc.stop()
    finally:
        svc.kill()
    (log,) = sorted(svc.logs.glob("run-*.mcap"))
    ev = [(e.joint, e.value) for e in read_flight_log(log).events if e.kind_name == "payload"]
    assert ev == [(-1, 2.0), (0, 0.01), (1, -0.02), (2, 0.06)] + [
        (-1, 0.5), (0, 0.01), (1, -0.02), (2, 0.06)
    ]  # fmt: skip
