"""Abusive clients against a real ``hofto-hw run --clock real --socket S``: a flood of
requests, a 10 MB line, a trickle of bytes, bytes that are not UTF-8, deep nesting, more
connections than allowed, a 300 s taught path planned and replayed. Throughout: ``stop`` is
answered, status too, and the loop latches no overrun (timings: tools/bench_control.py)."""

from __future__ import annotations

import socket
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from support.control_service import Service, connect_raw, settled, wait_for

from hofto_hw.client import Robot
from hofto_hw.client.connection import Connection
from hofto_hw.control.taught_path import TaughtPathRecorder, save_taught_path
from hofto_hw.control_plane import protocol as pr


@pytest.fixture(scope="module")
def service(tmp_path_factory: pytest.TempPathFactory):
    svc = Service(tmp_path_factory.mktemp("hard"), "--hold", "--no-collision", log=False)
    try:
        yield svc
    finally:
        svc.stop()


def _reply(s: socket.socket, timeout: float = 30.0) -> dict:
    s.settimeout(timeout)
    buf = b""
    while b"\n" not in buf:
        chunk = s.recv(65536)
        if not chunk:
            break
        buf += chunk
    return pr.parse_reply(buf.split(b"\n", 1)[0])


def _stop_and_reset(robot: Robot) -> None:
    assert robot.stop() == "stop requested"
    wait_for(lambda: robot.state().faults == ["stop_request"], "the stop latched")
    robot.reset()
    wait_for(lambda: robot.state().faults == [], "reset")


def _no_overrun(robot: Robot) -> None:
    st = robot.status()
    assert "overrun" not in st["faults"], st


def test_bad_lines_are_answered_in_one_line_and_the_connection_goes_on(service: Service) -> None:
    s = connect_raw(service.sock)
    try:
        cases = [
            (b'{"cmd": "st\xffatus"}\n', "not UTF-8"),
            (b"status\n", "not JSON"),
            (b'{"cmd": "status"', None),  # completed by the next line's bytes: not JSON
            (b"\n", "not JSON"),
            (b"[" * 1000 + b"]" * 1000 + b"\n", "nested deeper"),
            (b'{"cmd": "shutdown"}\n', "unknown cmd"),
            (b'{"cmd": "mode", "mode": "fly"}\n', "unknown mode"),
            (b'{"cmd": "move_joints", "q": [0,0,0,0,0,0], "speed": "fast"}\n', "speed"),
            (b'{"cmd": "status", "extra": 1}\n', "unknown field"),
            (b'{"cmd": "enable"}\n', "missing field 'on'"),
        ]
        for line, needle in cases:
            s.sendall(line)
            if needle is None:
                continue
            r = _reply(s)
            assert not r["ok"] and needle in r["message"], (line[:40], r)
            assert "\n" not in r["message"]
        s.sendall(pr.dumps({"cmd": "status"}))
        assert _reply(s)["ok"]  # still served
    finally:
        s.close()


def test_flood_10mb_trickle_and_idle_clients_never_delay_stop(service: Service) -> None:
    with Robot.connect(socket=service.sock) as robot:
        wait_for(lambda: robot.state().mode == "hold", "hold")
        done = threading.Event()
        errors: list[BaseException] = []

        def flood() -> None:
            line = pr.dumps({"cmd": "status"})
            while not done.is_set():
                try:
                    with connect_raw(service.sock) as s:
                        for _ in range(2000):  # never reads a reply
                            s.sendall(line)
                except OSError:
                    pass

        def big() -> None:
            while not done.is_set():
                try:
                    with connect_raw(service.sock) as s:
                        s.sendall(b"a" * (10 << 20))  # 10 MB, no newline
                except OSError:
                    pass

        def trickle() -> None:
            try:
                with connect_raw(service.sock) as s:
                    for b in b'{"cmd": "status"}':
                        if done.is_set():
                            return
                        s.sendall(bytes([b]))
                        time.sleep(0.5)
                    errors.append(AssertionError("a trickle was served to the end"))
            except OSError:
                pass

        idle = [connect_raw(service.sock) for _ in range(20)]  # more than the 16 allowed
        threads = [threading.Thread(target=f) for f in (flood, big, trickle)]
        for t in threads:
            t.start()
        try:
            for _ in range(5):
                _stop_and_reset(robot)  # each stop on a new connection, answered first
        finally:
            done.set()
            for t in threads:
                t.join()
            for s in idle:
                s.close()
        assert not errors, errors
        _no_overrun(robot)


def _long_path(model_n: int, home: np.ndarray, seconds: float, folder: Path) -> Path:
    rec = TaughtPathRecorder(model_n, int(seconds * 1000) + 1)
    t = np.arange(0.0, seconds, 1e-3)
    wave = 0.05 * (1.0 - np.cos(2 * np.pi * t / 20.0))
    for tk, w in zip(t, wave, strict=True):
        rec.push(tk, home + w)
    from support.control_service import CONFIG

    from hofto_hw.config.loader import load_config
    from hofto_hw.model.robot import RobotModel

    model = RobotModel.from_config(load_config(CONFIG).robot)
    return save_taught_path(rec.path(model), folder / "long.csv")


def test_300_s_replay_is_planned_off_the_loop_and_stop_answered_while_it_plays(
    service: Service, tmp_path: Path
) -> None:
    with Robot.connect(socket=service.sock) as robot:
        wait_for(settled(robot), "hold at rest")
        home = robot.state().q_cmd
        file = _long_path(6, home, 300.0, tmp_path)
        answered: list[bool] = []
        done = threading.Event()

        def ask() -> None:  # the service answers while it plans
            with Connection(service.sock) as c:
                while not done.is_set():
                    answered.append(c.call({"cmd": "status"})["ok"])
                    time.sleep(0.05)

        t = threading.Thread(target=ask)
        t.start()
        try:
            m = robot.replay(file, wait=False)
        finally:
            done.set()
            t.join()
        assert "replaying" in m.message and answered and all(answered)
        wait_for(lambda: (robot.status()["playback"] or {}).get("progress", 0) > 0.02, "playing")
        _stop_and_reset(robot)  # while it plays: answered, the arm stops
        _no_overrun(robot)
