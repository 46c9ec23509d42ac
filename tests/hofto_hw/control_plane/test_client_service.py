"""The Python client against a real ``hofto-hw run --clock real --socket S`` on the simulated
bus: stream, move, drag with the lease, a client killed mid-drag, ``on()``."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from support.control_service import ROOT, Service, children, settled, socket_config, wait_for

from hofto_hw.client import Refused, Robot


@pytest.fixture(scope="module")
def service(tmp_path_factory: pytest.TempPathFactory):
    tmp = tmp_path_factory.mktemp("svc")
    svc = Service(tmp, "--hold", "--no-collision")
    try:
        yield svc
    finally:
        svc.stop()


def test_stream_1000_states_at_100_hz_none_missed(service: Service) -> None:
    with Robot.connect(socket=service.sock) as robot:
        recs = list(robot.stream(rate_hz=100.0, count=1000))
    ticks = np.array([r.tick for r in recs])
    assert len(ticks) == 1000
    assert np.all(np.diff(ticks) == 10), "a state missed or repeated"
    assert sum(r.skipped for r in recs) == 0
    assert all(np.isfinite(r.q).all() and r.q.shape == (6,) for r in recs)


def test_state_is_a_typed_snapshot(service: Service) -> None:
    with Robot.connect(socket=service.sock) as robot:
        s = robot.state()
    assert s.q.shape == (6,) and s.qd.shape == (6,) and s.tau.shape == (6,)
    assert set(s.tau_ext) == {"hofto", "momentum"}
    assert s.tcp_position.shape == (3,) and s.tcp_rotation.shape == (3, 3)
    np.testing.assert_allclose(s.tcp_rotation @ s.tcp_rotation.T, np.eye(3), atol=1e-9)
    assert s.enabling.source == "socket" and not s.enabling.pressed
    assert s.faults == [] and s.category == -1 and s.tick > 0


def test_move_joints_waits_and_reaches_the_target(service: Service) -> None:
    with Robot.connect(socket=service.sock) as robot:
        wait_for(settled(robot), "hold at rest")
        q0 = robot.state().q_cmd
        target = q0 + np.array([0.1, -0.05, 0.05, 0.1, -0.1, 0.1])
        m = robot.move_joints(target, speed=0.5, acceleration=0.5, timeout=120.0)
        assert m.result == "completed"
        wait_for(settled(robot), "rest after the move")
        assert np.abs(robot.state().q - target).max() < 2e-3
        with pytest.raises(Refused, match="outside its limits"):
            robot.move_joints(q0 + np.array([0, 0, 9.0, 0, 0, 0]))
        m = robot.move_joints(q0, wait=True, timeout=120.0)  # back
        assert m.done


def test_move_linear_moves_the_tool_along_a_line(service: Service) -> None:
    with Robot.connect(socket=service.sock) as robot:
        wait_for(settled(robot), "hold at rest")
        s = robot.state()
        from scipy.spatial.transform import Rotation

        rv = Rotation.from_matrix(s.tcp_rotation).as_rotvec()
        start = np.concatenate([s.tcp_position, rv])
        target = start + np.array([0.03, 0.0, -0.02, 0, 0, 0])
        q_before = robot.state().q_cmd
        with pytest.raises(Refused, match="leaves the arm's reach"):
            robot.move_linear(start + np.array([2.0, 0, 0, 0, 0, 0]))
        assert np.array_equal(robot.state().q_cmd, q_before)  # refused before moving
        m = robot.move_linear(target, speed=0.5, timeout=120.0)
        assert m.result == "completed"
        wait_for(settled(robot), "rest after the line")
        assert np.abs(robot.state().tcp_position - target[:3]).max() < 1e-3
        robot.move_linear(start, timeout=120.0)  # back


def test_drag_holds_the_lease_and_another_client_is_refused(service: Service) -> None:
    with Robot.connect(socket=service.sock) as robot, Robot.connect(socket=service.sock) as other:
        wait_for(settled(robot), "hold at rest")
        with robot.drag():
            s = wait_for(lambda: (st := robot.state()).enabling.drag_active and st, "drag active")
            assert s.mode == "drag" and s.enabling.pressed
            with pytest.raises(Refused, match="held by client"):
                other.move_joints(s.q_cmd)
            # held for many leases: the renewals keep it
            t0 = s.t
            wait_for(lambda: robot.state().t > t0 + 4 * robot.lease_s, "four leases")
            s = robot.state()
            assert s.enabling.drag_active and s.faults == []
        wait_for(lambda: robot.state().mode == "hold", "hold after the drag")
        assert robot.state().faults == []


CLIENT = textwrap.dedent(
    """
    import sys, time
    from hofto_hw.client import Robot
    robot = Robot.connect(socket=sys.argv[1])
    with robot.drag():
        while not robot.state().enabling.drag_active:
            time.sleep(0.01)
        print("dragging", flush=True)
        time.sleep(600)
    """
)


@pytest.mark.parametrize("how", ["SIGKILL", "SIGSTOP"])
def test_client_killed_or_hung_mid_drag_stops_the_arm_category_2(
    service: Service, tmp_path: Path, how: str
) -> None:
    """SIGKILL: the connection closes (released at once); SIGSTOP: the connection stays and
    the lease lapses. Either way: enabling_released, category 2, the arm at rest."""
    with Robot.connect(socket=service.sock) as robot:
        wait_for(settled(robot), "hold at rest")
        env = {**os.environ, "PYTHONPATH": str(ROOT)}
        child = subprocess.Popen(
            [sys.executable, "-c", CLIENT, str(service.sock)],
            env=env,
            stdout=subprocess.PIPE,
            text=True,
        )
        try:
            assert child.stdout is not None
            assert child.stdout.readline().strip() == "dragging"
            child.send_signal(getattr(signal, how))
            s = wait_for(lambda: (st := robot.state()).faults and st, "a latched stop")
            assert s.faults == ["enabling_released"] and s.category == 2
            wait_for(lambda: float(np.abs(robot.state().qd).max()) < 0.01, "at rest")
        finally:
            child.kill()
            child.wait()
        robot.reset()
        assert robot.state().faults == []


def test_on_sees_the_scripted_collision(tmp_path: Path) -> None:
    svc = Service(tmp_path, config=socket_config(tmp_path, collision_start=6.0))
    try:
        seen: list[dict] = []
        with Robot.connect(socket=svc.sock) as robot:
            robot.on("collision", seen.append)
            wait_for(lambda: seen, "the collision event")
            assert seen[0]["kind"] == "collision" and seen[0]["category"] == 1
            assert "collision" in robot.state().faults
    finally:
        svc.stop()


def test_safety_profile_switch_refused_while_moving_accepted_at_standstill(tmp_path: Path) -> None:
    from hofto_hw.replay.flight_log import read_flight_log

    svc = Service(tmp_path, "--hold", "--no-collision")
    try:
        with Robot.connect(socket=svc.sock) as robot:
            assert robot.state().profile == "normal"
            wait_for(settled(robot), "hold at rest")
            q0 = robot.state().q_cmd
            m = robot.move_joints(q0 + 0.2, speed=0.1, acceleration=0.1, wait=False)  # seconds
            wait_for(lambda: robot.state().moving, "moving")
            with pytest.raises(Refused, match="changes at standstill"):
                robot.set_safety_profile("reduced")
            assert robot.state().profile == "normal"
            m.wait(timeout=120.0)
            wait_for(settled(robot), "at rest after the move")
            content = robot.set_safety_profile("reduced")
            assert content == {
                "collision_scale": 0.8, "speed_scale": 0.25, "drag_mass_scale": 1.0,
                "drag_damping_scale": 1.0, "drag_speed_scale": 0.5,
            }  # fmt: skip
            assert robot.state().profile == "reduced"
            assert robot.status()["profile"]["name"] == "reduced"
            with pytest.raises(Refused, match="not a profile"):
                robot.set_safety_profile("turbo")
        svc.stop()
    finally:
        svc.kill()
    (log,) = sorted(svc.logs.glob("run-*.mcap"))
    ev = [e for e in read_flight_log(log).events if e.kind_name == "profile"]
    assert len(ev) == 1 and ev[0].value == pytest.approx(0.8)
    assert ev[0].joint == ["contact-task", "normal", "reduced"].index("reduced")


def test_the_control_plane_watches_the_flight_recorder(tmp_path: Path) -> None:
    """The log watch runs in the control plane, not in a thread of the loop's process: a
    dead writer process still reaches the loop as log_failure."""
    svc = Service(tmp_path, "--hold", "--no-collision")
    try:
        (writer,) = [p for p, cmd in children(svc.proc.pid) if "hofto-hw-writer" in cmd]
        with Robot.connect(socket=svc.sock) as robot:
            assert "log_failure" not in robot.state().faults
            os.kill(writer, signal.SIGKILL)
            wait_for(lambda: "log_failure" in robot.state().faults, "log_failure")
            assert robot.status()["recorder"]["writer_alive"] is False
    finally:
        svc.kill()
