"""The clients against a service that answers wrongly, and ``hofto-hw run --socket`` with a
path that cannot be served: one line each, never a traceback, nothing left behind."""

from __future__ import annotations

import os
import socket
import threading
from pathlib import Path

import pytest
from support.cli import one_line_error

from hofto_hw.cli import main
from hofto_hw.client.connection import ServiceError
from hofto_hw.runtime.control_client import request

CONFIG = Path(__file__).resolve().parents[3] / "configs" / "er3a.yaml"


class FakeService:
    """Answers every connection's first line with ``reply`` (bytes; None: never answers)."""

    def __init__(self, path: Path, reply: bytes | None) -> None:
        self.path = path
        self.reply = reply
        self.srv = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        self.srv.bind(str(path))
        self.srv.listen(8)
        self.srv.settimeout(0.1)
        self.done = threading.Event()
        self.held: list[socket.socket] = []
        self.t = threading.Thread(target=self._serve, daemon=True)
        self.t.start()

    def _serve(self) -> None:
        while not self.done.is_set():
            try:
                c, _ = self.srv.accept()
            except TimeoutError:
                continue
            c.settimeout(5.0)
            try:
                c.recv(65536)
                if self.reply is None:
                    self.held.append(c)
                    continue
                c.sendall(self.reply)
            except OSError:
                pass
            c.close()

    def close(self) -> None:
        self.done.set()
        self.t.join()
        self.srv.close()
        for c in self.held:
            c.close()


STATUS_OK = (
    b'{"ok": true, "state": "running", "mode": "hold", "ticks": 1, "overruns": 0, '
    b'"faults": [], "persisting": [], "category": -1, "log": null, '
)
REPLIES = {
    "not json": b"this is not json\n",
    "truncated": b'{"ok": true, "state": "run\n',
    "closed early": b"",
    "not utf-8": b'{"ok": true, "message": "\xff\xfe"}\n',
    "deep nesting": b'{"ok": true, "x": ' + b"[" * 100000 + b"]" * 100000 + b"}\n",
    "ok NaN": b'{"ok": NaN}\n',
    "ok not bool": b'{"ok": "yes"}\n',
    "ok missing": b'{"message": "hi"}\n',
    "infinite number": b'{"ok": true, "message": "m", "x": 1e999}\n',
    "a list": b"[1, 2, 3]\n",
    "message not text": b'{"ok": true, "message": 5}\n',
    "no timing_us": STATUS_OK + b'"recorder": null}\n',
    "timing_us wrong": STATUS_OK + b'"timing_us": 5}\n',
    "faults a number": b'{"ok": true, "state": "running", "mode": "hold", "ticks": 1, '
    b'"overruns": 0, "faults": 5, "persisting": [], "category": -1, "log": null, '
    b'"timing_us": {"compute": {"median": 1, "p99": 2}, "wakeup": {"median": 1, "p99": 2}}}\n',
}


@pytest.mark.parametrize("case", list(REPLIES))
@pytest.mark.parametrize("command", [["status"], ["stop"], ["reset"], ["mode", "hold"]])
def test_every_malformed_reply_is_one_line(tmp_path: Path, capsys, case: str, command) -> None:
    fake = FakeService(tmp_path / "s.sock", REPLIES[case])
    try:
        code = main([*command, "--socket", str(fake.path)])
        out, err = capsys.readouterr()
    finally:
        fake.close()
    if command == ["status"] or case not in ("no timing_us", "timing_us wrong", "faults a number"):
        one_line_error(code, err, str(fake.path))
    else:  # stop/reset/mode only print the message: a valid reply for them
        assert code in (0, 1) and "Traceback" not in err


def test_no_answer_is_one_line_after_the_timeout(tmp_path: Path) -> None:
    fake = FakeService(tmp_path / "s.sock", None)
    try:
        with pytest.raises(ServiceError, match=r"no answer within 0.3 s") as e:
            request(fake.path, "status", timeout=0.3)
        assert "\n" not in str(e.value)
    finally:
        fake.close()


def _segments() -> set[str]:
    return set(os.listdir("/dev/shm")) if os.path.isdir("/dev/shm") else set()


def _bad_socket_paths(tmp_path: Path) -> dict[str, tuple[str, str]]:
    long_dir = tmp_path / ("d" * 100)
    long_dir.mkdir()
    plain = tmp_path / "plain"
    plain.write_text("keep me")
    return {
        "too long": (str(long_dir / "control.sock"), "a Unix socket path holds at most 107"),
        "in /proc": ("/proc/self/control.sock", "under /proc"),
        "missing folder": (str(tmp_path / "no" / "c.sock"), "does not exist"),
        "a file": (str(plain), "not a socket"),
        "a folder": (str(tmp_path), "is a folder"),
    }


def test_bad_socket_paths_are_one_line_and_leave_nothing(tmp_path: Path, capsys) -> None:
    logs = tmp_path / "logs"
    for what, (path, needle) in _bad_socket_paths(tmp_path).items():
        before = _segments()
        code = main(
            ["run", "--config", str(CONFIG), "--clock", "sim", "--duration", "0.1",
             "--log-dir", str(logs), "--socket", path]
        )  # fmt: skip
        _, err = capsys.readouterr()
        one_line_error(code, err, "--socket", needle)
        assert not logs.exists() or not list(logs.iterdir()), what  # no empty run-*.mcap
        assert _segments() <= before, what  # no shared-memory segment left
    assert (tmp_path / "plain").read_text() == "keep me"
