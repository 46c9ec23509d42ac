"""A taught path longer than the plan ring, through a real ``hofto-hw run --clock real --socket
S``: the planner sends it in chunks the loop plays as they come (the ring holds 4 s); the
arm follows it to its end with nothing latched. Timing (missed deadlines, wake-up p99 while
planning and playing a 300 s path): tools/bench_control.py."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from support.control_service import CONFIG, Service, settled, wait_for

from hofto_hw.client import Refused, Robot
from hofto_hw.config.loader import load_config
from hofto_hw.control.taught_path import TaughtPathRecorder, save_taught_path
from hofto_hw.model.robot import RobotModel

SECONDS = 20.0  # 20,000 rows: five plan rings, 79 planner chunks


def _path(home: np.ndarray, folder: Path) -> Path:
    """A rise of 0.1 rad on every joint and back ((1 - cos)/2 over SECONDS)."""
    model = RobotModel.from_config(load_config(CONFIG).robot)
    rec = TaughtPathRecorder(model.n, int(SECONDS * 1000) + 1)
    for tk in np.arange(0.0, SECONDS, 1e-3):
        rec.push(tk, home + 0.05 * (1.0 - np.cos(2 * np.pi * tk / SECONDS)))
    return save_taught_path(rec.path(model), folder / "long.csv")


def test_a_path_longer_than_the_plan_ring_is_streamed_and_followed_to_its_end(
    tmp_path: Path,
) -> None:
    svc = Service(tmp_path, "--hold", "--no-collision", log=False)
    try:
        with Robot.connect(socket=svc.sock) as robot:
            wait_for(settled(robot), "hold at rest")
            home = robot.state().q_cmd
            file = _path(home, tmp_path)
            m = robot.replay(file, wait=False)
            assert "replaying" in m.message and "along it" in m.message
            top = np.zeros(6)
            end = time.monotonic() + 600.0  # a state reached, not a time: a generous bound
            while not m.done:  # the arm along the path, sampled as it plays
                assert time.monotonic() < end, "the replay did not end (a starved plan holds)"
                s = robot.state()
                assert s.faults == [], s.faults
                top = np.maximum(top, s.q - home)
                time.sleep(0.02)
            assert m.result == "completed", m.result
            s = robot.state()
            assert s.faults == [] and s.mode == "hold", (s.faults, s.mode)
            np.testing.assert_allclose(top, 0.1, atol=3e-3)  # its top, every joint
            np.testing.assert_allclose(s.q, home, atol=3e-3)  # and back where it began
            try:
                robot.replay(file, wait=False).cancel()  # a second plan after the first
            except Refused as exc:  # (planning refused only for a reason it names)
                raise AssertionError(str(exc)) from None
    finally:
        svc.stop()
