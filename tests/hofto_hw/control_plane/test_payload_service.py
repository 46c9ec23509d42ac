"""``Robot.set_payload`` and ``hofto-hw payload set`` against a real ``hofto-hw run --clock
real --socket S`` on the simulated bus whose arm holds 2 kg the config does not know: the
estimates at rest show the load's weight until the payload is set, go to ~0 with the right
one, show the missing part with a wrong one; refused while moving, outside the rating and
when its holding torque does not fit the joints' torque limits; ramped in over
``robot.rated_payload.ramp_s`` (the model's holding torque moves step by step, not at once);
shown by state() and status(); flight-log events with its values, which replay takes."""

from __future__ import annotations

import os
import socket
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml
from support.control_service import ROOT, Service, settled, socket_config, wait_for

from hofto_hw.client import Refused, Robot
from hofto_hw.config.loader import load_config
from hofto_hw.control_plane import protocol as pr
from hofto_hw.control_plane.server import RAMP_STEP_S
from hofto_hw.model.payload import Payload, apply_payload
from hofto_hw.runtime.compose import build_model

COM = [0.01, -0.02, 0.06]
RAMP_S = 0.5
STEPS = 25  # ceil(RAMP_S / RAMP_STEP_S)


def _config(tmp: Path) -> Path:
    path = socket_config(tmp)
    data = yaml.safe_load(path.read_text())
    data["safety"]["payload"] = {"mass": 0.0}
    data["run"]["simulated_payload"] = {"mass": 2.0, "com": COM}
    data["run"]["model_error"] = 0.0  # the load is what differs
    data["safety"].pop("collision")  # an unmodelled load is measured here, not stopped
    data["robot"]["rated_payload"]["ramp_s"] = RAMP_S
    # the shoulder's torque limit below its worst holding torque with 3 kg (48 N·m with the
    # arm stretched out), above it with 2 kg (42 N·m)
    data["robot"].setdefault("limits", {})["torque"] = [120.0, 45.0, 60.0, 15.0, 15.0, 10.0]
    path.write_text(yaml.safe_dump(data))
    return path


def _weight(cfg, q: np.ndarray, mass: float) -> np.ndarray:
    """The observers' view of ``mass`` at COM the model lacks: -(g with it - g without)."""
    bare, loaded = build_model(cfg), build_model(cfg)
    apply_payload(loaded, Payload(mass, tuple(COM)))
    return bare.create_data().gravity(q) - loaded.create_data().gravity(q)


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
            wait_for(settled(robot), "hold at rest")
            q0 = robot.state().q_cmd
            m = robot.move_joints(q0 + 0.2, speed=0.1, acceleration=0.1, wait=False)
            wait_for(lambda: robot.state().moving, "moving")
            with pytest.raises(Refused, match="changes at standstill"):
                robot.set_payload(2.0, COM)
            m.wait(timeout=120.0)
            wait_for(settled(robot), "at rest after the move")
            with pytest.raises(Refused, match=r"within \[0, 3\] kg"):
                robot.set_payload(5.0, COM)
            with pytest.raises(Refused, match=r"com_max = 0\.15 m"):
                robot.set_payload(1.0, [0.0, 0.0, 0.5])
            with pytest.raises(Refused) as refused:
                robot.set_payload(3.0, [0.0, 0.0, 0.05])
            assert str(refused.value).startswith(
                "set_payload: 3 kg at com [0.0, 0.0, 0.05] m: joint_2 would hold 48."
            )
            assert str(refused.value).endswith("rad), more than its torque limit 45 N·m")
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

            # a new payload during a ramp supersedes it: two requests on one connection,
            # the second read while the first ramps (each step answered in turn)
            with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as raw:
                raw.connect(str(svc.sock))
                for i, mass in ((1, 1.0), (2, 1.5)):
                    raw.sendall(pr.dumps({"cmd": "set_payload", "mass": mass, "com": COM, "id": i}))
                replies = _replies(raw, 2)
            assert replies[1]["ok"] is False and "superseded" in replies[1]["message"]
            assert replies[2]["ok"] is True and replies[2]["payload"]["mass"] == 1.5
            assert robot.state().payload.mass == 1.5
        svc.stop()
    finally:
        svc.kill()
    (path,) = sorted(svc.logs.glob("run-*.mcap"))
    log = read_flight_log(path)
    from hofto_hw.replay.reproduce import payload_changes

    steps = payload_changes(log)  # (tick, Payload) of each intermediate payload the loop took
    t_of = {e.tick: e.t for e in log.events}  # loop time of each event's tick [s]
    up, down, last = steps[:STEPS], steps[STEPS : 2 * STEPS], steps[2 * STEPS :]
    # the superseded ramp: some steps from 0.5 toward 1.0, then 1.5 from the last one taken
    masses = [p.mass for _, p in last]
    assert masses[-1] == pytest.approx(1.5) and 0.5 < masses[0] < 1.0
    assert len(masses) <= 2 * STEPS and all(np.diff(masses) > 0.0), masses
    for ramp, start, end in ((up, 0.0, 2.0), (down, 2.0, 0.5)):
        masses = [p.mass for _, p in ramp]
        assert masses[-1] == pytest.approx(end) and all(np.allclose(p.com, COM) for _, p in ramp)
        step = (end - start) / STEPS
        np.testing.assert_allclose(np.diff([start, *masses]), step, rtol=1e-9)
        # spread over ramp_s: step k is due at k/N of it (the control plane's clock), the
        # loop takes it at its next tick. Loop time, not ticks: a missed deadline is time
        # without a tick (CI once counted 479 ticks over the 480 ms); one step's time of
        # slack for when the loop took the first and the last step
        span = t_of[ramp[-1][0]] - t_of[ramp[0][0]]  # [s]
        assert span >= RAMP_S * (STEPS - 1) / STEPS - RAMP_STEP_S, span

        # the feed-forward's holding torque (the model's gravity with each step's payload
        # at the pose of its tick) moves in STEPS equal steps: monotonic, none a jump
        def k(tick: int) -> int:  # its record, or the next one (a loaded machine's writer
            return min(int(np.searchsorted(log.ticks, tick)), len(log.ticks) - 1)  # drops some

        g = np.array([-_weight(cfg, log.q[k(t)], p.mass)[1] for t, p in ramp])
        g0 = -_weight(cfg, log.q[k(ramp[0][0])], start)[1]
        d = np.diff([g0, *g])
        assert (np.sign(d) == np.sign(d[0])).all() and d[0] != 0.0, d  # monotonic
        assert (abs(g[-1]) > abs(g0)) == (end > start)  # more load: more holding torque
        assert np.abs(d).max() < 1.5 * abs(g[-1] - g0) / STEPS  # no jump

    # (replay takes every step at its tick and MATCHes: test_replay_switches.py, whose
    # set_payload is ramped in by the default robot.rated_payload.ramp_s)


def _replies(s: socket.socket, n: int, timeout: float = 60.0) -> dict[int, dict]:
    """The next ``n`` reply lines on ``s``, by their id."""
    s.settimeout(timeout)
    buf = b""
    while buf.count(b"\n") < n:
        chunk = s.recv(65536)
        if not chunk:
            break
        buf += chunk
    out = {}
    for line in buf.split(b"\n")[:n]:
        rep = pr.parse_reply(line)
        out[int(rep["id"])] = rep
    return out
