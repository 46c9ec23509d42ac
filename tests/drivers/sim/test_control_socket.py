"""drivers/sim/control_socket.py ControlConnections: an emulator's frame loop serves its
control socket without ever waiting for a client (one that connected and sent nothing yet,
one that reads a long reply slowly), and every client still gets its whole answer."""

from __future__ import annotations

import json
import select
import socket
import threading
import time
from pathlib import Path
from typing import Any

import pytest

from drivers.sim import control_socket as cs
from drivers.sim.control_socket import ControlConnections, open_control_socket

BIG = 400_000  # characters of a reply: more than a Unix socket's buffer takes at once


@pytest.fixture(autouse=True)
def _patient(monkeypatch: pytest.MonkeyPatch) -> None:
    """Clients are not dropped while a loaded machine keeps them (or the loop) off the CPU:
    the drop is the last test's, with its own timeout."""
    monkeypatch.setattr(cs, "CLIENT_TIMEOUT", 600.0)


def _handler(request: dict[str, Any]) -> dict[str, Any]:
    if request.get("op") == "big":
        return {"ok": True, "data": "x" * BIG}
    return {"ok": True, "echo": request}


class FrameLoop:
    """A stand-in for the emulator's serve(): a select loop that counts its iterations
    ("frames") and serves the control socket beside them, in a thread."""

    def __init__(self, path: Path) -> None:
        self.srv = open_control_socket(str(path))
        self.clients = ControlConnections(self.srv, self._handle)
        self.frames = 0
        self.handled = 0  # counted before the reply leaves (a client that has it sees it)
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)

    def _handle(self, request: dict[str, Any]) -> dict[str, Any]:
        self.handled += 1
        return _handler(request)

    def _run(self) -> None:
        while not self.stop.is_set():
            r, w, _ = select.select(self.clients.readers(), self.clients.writers(), [], 0.001)
            self.clients.ready(r, w)
            self.frames += 1

    def frames_during(self, seconds_of_frames: int) -> int:
        """Wait for ``seconds_of_frames`` more iterations (a state, bounded by 30 s)."""
        start = self.frames
        end = time.monotonic() + 30.0
        while self.frames < start + seconds_of_frames:
            assert time.monotonic() < end, "the frame loop stopped going round"
            time.sleep(0.001)
        return self.frames - start

    def __enter__(self) -> FrameLoop:
        self.thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop.set()
        self.thread.join(5.0)
        self.clients.close()
        self.srv.close()


def _call(path: Path, request: dict[str, Any]) -> dict[str, Any]:
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as s:
        s.settimeout(10.0)
        s.connect(str(path))
        s.sendall(json.dumps(request).encode() + b"\n")
        data = b""
        while not data.endswith(b"\n"):
            chunk = s.recv(65536)
            assert chunk, f"connection closed after {len(data)} bytes"
            data += chunk
    return json.loads(data)


def test_a_request_is_answered_from_the_loop(tmp_path: Path) -> None:
    path = tmp_path / "ctl.sock"
    with FrameLoop(path) as loop:
        assert _call(path, {"op": "status", "n": 3}) == {
            "ok": True,
            "echo": {"op": "status", "n": 3},
        }
        assert _call(path, {"op": "big"})["data"] == "x" * BIG  # sent across many writes
        bad = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        bad.connect(str(path))
        bad.sendall(b"{not json\n")
        bad.settimeout(10.0)
        assert "bad JSON" in json.loads(bad.recv(65536))["error"]
        bad.close()
        assert loop.handled == 2  # the bad line is answered without the handler


def test_a_client_that_sends_nothing_or_reads_slowly_holds_up_no_frame(tmp_path: Path) -> None:
    path = tmp_path / "ctl.sock"
    with FrameLoop(path) as loop:
        silent = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        silent.connect(str(path))  # connected, its line not sent (a preempted client)
        slow = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        slow.connect(str(path))
        slow.sendall(b'{"op": "big"}\n')  # its long reply not read yet
        # the loop goes round while both wait (it used to block in recv / sendall)
        assert loop.frames_during(200) >= 200
        assert _call(path, {"op": "status"})["ok"]  # another client is served meanwhile
        silent.sendall(b'{"op": "late"}\n')
        silent.settimeout(10.0)
        assert json.loads(silent.recv(65536))["echo"] == {"op": "late"}
        slow.settimeout(10.0)
        data = b""
        while not data.endswith(b"\n"):
            data += slow.recv(65536)
        assert json.loads(data)["data"] == "x" * BIG
        silent.close()
        slow.close()


def test_a_client_that_never_sends_its_line_is_dropped(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(cs, "CLIENT_TIMEOUT", 0.05)
    path = tmp_path / "ctl.sock"
    with FrameLoop(path) as loop:
        silent = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        silent.connect(str(path))
        silent.settimeout(10.0)
        assert silent.recv(100) == b""  # closed by the loop after the timeout
        silent.close()
        assert loop.handled == 0
        assert _call(path, {"op": "status"})["ok"]
