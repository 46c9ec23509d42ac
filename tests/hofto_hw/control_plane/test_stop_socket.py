"""The stop socket (``<control socket>.stop``, hofto_hw/control_plane/stop_server.py) of a
real ``hofto-hw run --clock real --socket S`` on the simulated bus: a stop there is answered
once the loop has acknowledged it and latches ``stop_request`` while other processes flood
the control socket; a malformed line is refused in one line and stops nothing; the CLI and
the client use it and fall back to the control socket without it; it is removed at exit; a
stop-socket path that breaks the socket rules is one line. Timings: tools/bench_control.py."""

from __future__ import annotations

import importlib.util
import multiprocessing as mp
import os
import socket
import stat
from pathlib import Path

import pytest
from support.cli import one_line_error
from support.control_service import Service, connect_raw, wait_for

from hofto_hw.cli import main
from hofto_hw.client import Robot
from hofto_hw.control_plane import protocol as pr
from hofto_hw.control_plane.protocol import stop_path

ROOT = Path(__file__).resolve().parents[3]
CONFIG = ROOT / "configs" / "er3a.yaml"


@pytest.fixture(scope="module")
def service(tmp_path_factory: pytest.TempPathFactory):
    svc = Service(tmp_path_factory.mktemp("stopsock"), "--hold", "--no-collision", log=False)
    try:
        yield svc
    finally:
        svc.stop()


def _ask(path: Path, data: bytes, close_write: bool = False) -> tuple[dict, bytes]:
    """Send ``data`` on a new connection; (the one reply line parsed, what followed it
    before the service closed the connection)."""
    with connect_raw(path) as s:
        s.sendall(data)
        if close_write:
            s.shutdown(socket.SHUT_WR)
        s.settimeout(60.0)
        buf = b""
        while True:
            chunk = s.recv(65536)
            if not chunk:
                break
            buf += chunk
    line, _, rest = buf.partition(b"\n")
    return pr.parse_reply(line), rest


# the benchmark's abusers of the control socket, each run as a process of its own
_spec = importlib.util.spec_from_file_location("bench_control", ROOT / "tools" / "bench_control.py")
_bench = importlib.util.module_from_spec(_spec)  # type: ignore[arg-type]
_spec.loader.exec_module(_bench)  # type: ignore[union-attr]


def _faults(robot: Robot) -> list[str]:
    return robot.state().faults


def _reset(robot: Robot) -> None:
    robot.reset()
    wait_for(lambda: _faults(robot) == [], "reset")


def test_a_stop_on_the_stop_socket_is_acknowledged_and_latched_while_others_flood_the_control_socket(  # noqa: E501
    service: Service,
) -> None:
    sp = stop_path(service.sock)
    with Robot.connect(socket=service.sock) as robot:
        wait_for(lambda: robot.state().mode == "hold", "hold")
        ctx = mp.get_context("fork")
        done = ctx.Event()
        procs = [
            ctx.Process(target=f, args=(service.sock, done), daemon=True)
            for f in (_bench.flood, _bench.big_line, *[_bench.trickle] * 4, _bench.idle)
        ]
        for p in procs:
            p.start()
        try:
            for i in range(3):
                before = robot.state().tick
                rep, rest = _ask(sp, pr.dumps({"cmd": "stop", "id": 7 + i}))
                assert rep["ok"] is True and rep["message"] == "stop requested", rep
                assert rep["acknowledged"] is True and rep["id"] == 7 + i and rest == b""
                assert rep["tick"] >= before  # the loop's tick count when it saw the stop
                assert rep["ack_ns"] >= rep["read_ns"] > 0 and rep["server_ms"] >= 0.0
                wait_for(lambda: _faults(robot) == ["stop_request"], "the stop latched")
                _reset(robot)  # through the flooded control socket
            assert robot.stop() == "stop requested" and robot.stop_note == ""  # the client's
            wait_for(lambda: _faults(robot) == ["stop_request"], "the client's stop latched")
            _reset(robot)
        finally:
            done.set()
            for p in procs:
                p.join(timeout=30.0)
                if p.is_alive():
                    p.kill()
        assert "overrun" not in robot.status()["faults"]


@pytest.mark.parametrize(
    ("data", "needle", "close_write"),
    [
        (b"st\xffop\n", "not UTF-8", False),
        (b"stopp\n", "not JSON", False),
        (b'{"cmd": "status"}\n', 'takes {"cmd": "stop"} only', False),
        (b'{"cmd": "stop"\n', "not JSON", False),
        (b"\n", "empty", False),
        (b"x" * 300, "longer than 256 bytes", False),
        (b'{"cmd": "stop"}', "closed before a complete line", True),
    ],
)
def test_a_malformed_line_on_the_stop_socket_is_refused_in_one_line_and_stops_nothing(
    service: Service, data: bytes, needle: str, close_write: bool
) -> None:
    with Robot.connect(socket=service.sock) as robot:
        wait_for(lambda: robot.state().mode == "hold" and not _faults(robot), "hold")
        rep, rest = _ask(stop_path(service.sock), data, close_write)
        assert rep["ok"] is False and rep["input_error"] is True, rep
        assert needle in rep["message"] and "\n" not in rep["message"] and rest == b""
        seen = robot.state().tick
        wait_for(lambda: robot.state().tick > seen + 50, "50 more ticks")
        assert _faults(robot) == [] and not robot._call({"cmd": "state"})["stop_requested"]


def test_the_bare_word_stop_stops(service: Service) -> None:
    with Robot.connect(socket=service.sock) as robot:
        wait_for(lambda: robot.state().mode == "hold" and not _faults(robot), "hold")
        rep, _ = _ask(stop_path(service.sock), b"STOP\r\n")  # e.g. typed into socat
        assert rep["ok"] is True and rep["acknowledged"] is True
        wait_for(lambda: _faults(robot) == ["stop_request"], "the stop latched")
        _reset(robot)


def test_cli_stop_uses_the_stop_socket_falls_back_without_it_and_both_sockets_go_at_exit(
    tmp_path: Path, capsys
) -> None:
    svc = Service(tmp_path, "--hold", "--no-collision", log=False)
    sp = stop_path(svc.sock)
    try:
        assert stat.S_ISSOCK(sp.lstat().st_mode)
        assert stat.S_IMODE(sp.lstat().st_mode) == stat.S_IMODE(svc.sock.lstat().st_mode)
        with Robot.connect(socket=svc.sock) as robot:
            wait_for(lambda: robot.state().mode == "hold", "hold")
            assert main(["stop", "--socket", str(svc.sock)]) == 0
            out, err = capsys.readouterr()
            assert out.strip() == "stop requested" and err == ""
            wait_for(lambda: _faults(robot) == ["stop_request"], "the stop latched")
            _reset(robot)
            hidden = sp.with_name("hidden")
            os.rename(sp, hidden)  # as an older service, which has no stop socket
            try:
                assert main(["stop", "--socket", str(svc.sock)]) == 0
                out, err = capsys.readouterr()
                assert out.strip() == "stop requested"
                assert "no stop socket" in err and "through the control socket" in err
                assert err.count("\n") == 1
                wait_for(lambda: _faults(robot) == ["stop_request"], "the fallback latched")
                _reset(robot)
                with pytest.warns(RuntimeWarning, match="through the control socket"):
                    assert robot.stop() == "stop requested"
                assert "no stop socket" in robot.stop_note
                wait_for(lambda: _faults(robot) == ["stop_request"], "the client's latched")
            finally:
                os.rename(hidden, sp)
    finally:
        svc.stop()
    assert not svc.sock.exists() and not os.path.lexists(sp)


def _segments() -> set[str]:
    """This process's shared-memory segments (the run below is ``main`` in it; other
    processes on the machine make and remove their own meanwhile)."""
    return {p.name for p in Path("/dev/shm").glob(f"hofto-hw-{os.getpid()}-*")}


def test_a_stop_socket_path_breaking_the_rules_is_one_line_and_leaves_nothing(
    tmp_path: Path, capsys
) -> None:
    logs = tmp_path / "logs"
    # the control socket's path fits (104 bytes), its stop socket's (109) does not
    folder = tmp_path / ("d" * max(1, 104 - len(os.fsencode(tmp_path)) - 1 - len("/c.sock")))
    folder.mkdir()
    long_ctl = folder / "c.sock"
    assert len(os.fsencode(long_ctl)) <= 107 < len(os.fsencode(stop_path(long_ctl)))
    taken = tmp_path / "t.sock"
    stop_path(taken).write_text("keep me")  # a file where the stop socket would go
    cases = [
        (long_ctl, "a Unix socket path holds at most 107"),
        (taken, "not a socket"),
    ]
    for path, needle in cases:
        before = _segments()
        code = main(
            ["run", "--config", str(CONFIG), "--clock", "sim", "--duration", "0.1",
             "--log-dir", str(logs), "--socket", str(path)]
        )  # fmt: skip
        _, err = capsys.readouterr()
        one_line_error(code, err, "--socket", needle)
        assert "stop socket" in err
        assert not os.path.lexists(path)  # the control socket was not created either
        assert not logs.exists() or not list(logs.iterdir())
        assert _segments() <= before
    assert stop_path(taken).read_text() == "keep me"
