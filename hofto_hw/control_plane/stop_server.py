"""The stop socket: a stop that queues behind nothing, served by a process of its own.

Beside the control socket ``S`` the service listens at ``S.stop`` (:func:`stop_path`; the
same path rules, checked before anything is created, :func:`check_stop_path`; the same
mode; removed at exit). A small process (``python -m hofto_hw.control_plane.stop_server``,
started by :class:`~hofto_hw.control_plane.process.ControlPlaneProcess`) does nothing but
accept, read one line of at most :data:`MAX_STOP_LINE` bytes per connection, write the
channel's ``STOP_FAST_SEQ`` word (the loop polls it first thing after every tick and sets
its stop request), wait for the loop's acknowledgement (``STOP_FAST_ACK``) and answer:
``{"ok": true, "message": "stop requested", "acknowledged": true, "tick": <the loop's tick
count when it saw it>, "server_ms": <from the line read to the acknowledgement>, "read_ns",
"ack_ns": <CLOCK_MONOTONIC of both>}``. No
request of the control socket, no planning, no status and no client of the control socket
can delay it: they live in another process with its own GIL.

What is a stop: the line ``{"cmd": "stop"}`` (any other fields, e.g. ``"id"``, are echoed or
ignored) or the bare word ``stop`` (``echo stop | socat - UNIX-CONNECT:S.stop``). Anything
else (not UTF-8, not JSON, another command, a line longer than 256 bytes, no complete line
within :data:`LINE_TIMEOUT`) is refused in one line and does **not** stop the arm: the
socket may be probed by a wrong tool (a status request sent to the wrong path), and a stop
latches until someone resets it. A well-formed stop is taken in every spelling a person or
a program would use; once its line is read it is acted on even when the client has gone.

Scheduling: the process sleeps in ``select`` and computes for microseconds per stop, so it
runs at SCHED_FIFO one below the loop's ``loop.priority`` when the loop runs real time
(``loop.realtime`` not ``off``) and the process may: ahead of every normal process
(the control plane, the recorder's writer, any client or abuser), never ahead of the loop.
Without the privilege it takes the lowest nice value it may (else it stays as started). When
the loop is pinned (``loop.cpus``) it runs on the other CPUs, as the control plane does.
"""

from __future__ import annotations

import gc
import os
import pickle
import selectors
import signal
import socket
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from hofto_hw.control_plane import channel as ch
from hofto_hw.control_plane import protocol as pr
from hofto_hw.control_plane.protocol import stop_path
from hofto_hw.errors import UserError

MAX_STOP_LINE = 256  # [bytes] of a stop line (the real one is 28)
LINE_TIMEOUT = 2.0  # [s] for a connection to send its line
ACK_TIMEOUT = 2.0  # [s] for the loop to acknowledge a stop (it does in its next poll)
MAX_CONNS = 64  # open connections; one more closes the oldest without a complete line
ACK_POLL = 0.0002  # [s] between looks at the acknowledgement word while a stop waits
IDLE_POLL = 0.2  # [s] between looks at LOOP_DONE and the parent when nothing happens


def check_stop_path(control: Path | str, option: str = "--socket") -> Path:
    """The stop socket's path, checked by the control socket's rules (length, folder,
    /proc and /sys, nothing but a stale socket there); UserError, one line naming
    ``option``."""
    from hofto_hw.control_plane.process import check_socket_path

    try:
        return check_socket_path(stop_path(control), option)
    except UserError as exc:
        raise UserError(f"{exc} (the stop socket beside the control socket)") from None


def parse_stop(raw: bytes) -> tuple[bool, str, Any]:
    """One line (without its newline) -> (is a stop, the refusal when not, the request's id)."""
    if len(raw) > MAX_STOP_LINE:
        return False, f"stop socket: a line longer than {MAX_STOP_LINE} bytes", None
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        return False, f"stop socket: the line is not UTF-8 (byte {exc.start})", None
    if text.strip().lower() == "stop":
        return True, "", None
    try:
        req = pr.loads_line(raw, MAX_STOP_LINE, "stop socket: the line")
    except pr.ProtocolError as exc:
        return False, f'{exc}; this socket takes {{"cmd": "stop"}} only', None
    rid = req.get("id")
    rid = rid if isinstance(rid, (int, str)) and not isinstance(rid, bool) else None
    if req.get("cmd") == "stop":
        return True, "", rid
    return (
        False,
        f"stop socket: cmd {pr._short(req.get('cmd', 'missing'))} refused: this socket takes "
        '{"cmd": "stop"} only (everything else goes to the control socket)',
        rid,
    )


@dataclass
class _Conn:
    sock: socket.socket
    opened: float
    buf: bytearray = field(default_factory=bytearray)
    read_at: float = 0.0  # when its stop line was read
    target: int = 0  # the STOP_FAST_SEQ value its stop wrote (0: none yet)
    rid: Any = None


class StopServer:
    """The stop socket's server (see the module docstring) on ``listener`` (listening),
    against ``chan`` (attached)."""

    def __init__(self, listener: socket.socket, chan: ch.Channel) -> None:
        listener.setblocking(False)
        self.listener = listener
        self.chan = chan
        self.ctl = chan.ctl
        self.sel = selectors.DefaultSelector()
        self.sel.register(listener, selectors.EVENT_READ)
        self.conns: dict[int, _Conn] = {}
        self.waiting: list[_Conn] = []
        self.seq = int(self.ctl[ch.STOP_FAST_SEQ])
        self.stops = 0
        self.refused = 0

    def serve(self, done: Any) -> None:
        """Until ``done()`` (checked at least every IDLE_POLL)."""
        while not done():
            self.turn(ACK_POLL if self.waiting else IDLE_POLL)
        for c in list(self.waiting):  # the loop has ended: it stopped the arm on its way out
            self._answer(c, {"ok": False, "message": "the service's loop has ended"})
        for c in list(self.conns.values()):
            self._close(c)

    def turn(self, timeout: float) -> None:
        """One select round: new connections, their lines, acknowledgements, time-outs."""
        for key, _ in self.sel.select(timeout):
            if key.fileobj is self.listener:
                self._accept()
            else:
                c = self.conns.get(key.fd)  # type: ignore[arg-type]
                if c is not None:
                    self._read(c)
        now = time.monotonic()
        if self.waiting:
            ack = int(self.ctl[ch.STOP_FAST_ACK])
            for c in [c for c in self.waiting if ack >= c.target]:
                rep = {
                    "ok": True,
                    "message": "stop requested",
                    "acknowledged": True,
                    "tick": int(self.ctl[ch.TICKS]),
                    "server_ms": round((now - c.read_at) * 1e3, 3),
                    # CLOCK_MONOTONIC [ns] of the line read and of the acknowledgement seen:
                    # a client (tools/bench_control.py) tells its own delays from ours
                    "read_ns": int(c.read_at * 1e9),
                    "ack_ns": int(now * 1e9),
                }
                self._answer(c, rep)
            for c in [c for c in self.waiting if now - c.read_at > ACK_TIMEOUT]:
                self._answer(
                    c,
                    {
                        "ok": False,
                        "message": f"stop requested, but the loop has not acknowledged it "
                        f"within {ACK_TIMEOUT:g} s",
                    },
                )
        for c in list(self.conns.values()):
            if not c.target and now - c.opened > LINE_TIMEOUT:
                self._refuse(c, f"stop socket: no complete line within {LINE_TIMEOUT:g} s")

    def _accept(self) -> None:
        while True:
            try:
                s, _ = self.listener.accept()
            except (BlockingIOError, InterruptedError):
                return
            except OSError:
                return  # EMFILE and the like: the next turn tries again
            s.setblocking(False)
            if len(self.conns) >= MAX_CONNS:  # the oldest without a line makes room
                idle = [c for c in self.conns.values() if not c.target]
                if idle:
                    self._refuse(min(idle, key=lambda c: c.opened), "stop socket: too many "
                                 "connections without a line; closed to make room")  # fmt: skip
            c = _Conn(s, time.monotonic())
            self.conns[s.fileno()] = c
            self.sel.register(s, selectors.EVENT_READ)
            self._read(c)  # its line is often there already: no select round

    def _read(self, c: _Conn) -> None:
        if c.target:  # answered once acknowledged; anything more it sends is ignored
            try:
                c.sock.recv(4096)
            except OSError:
                pass
            return
        try:
            data = c.sock.recv(MAX_STOP_LINE + 1 - len(c.buf))
        except (BlockingIOError, InterruptedError):
            return
        except OSError:
            self._close(c)
            return
        if not data:
            if c.buf:
                self._refuse(c, "stop socket: the connection closed before a complete line")
            else:
                self._close(c)
            return
        c.buf += data
        i = c.buf.find(b"\n")
        if i < 0:
            if len(c.buf) > MAX_STOP_LINE:
                self._refuse(c, f"stop socket: a line longer than {MAX_STOP_LINE} bytes")
            return
        is_stop, why, rid = parse_stop(bytes(c.buf[:i]).rstrip(b"\r"))
        c.rid = rid
        if not is_stop:
            self._refuse(c, why)
            return
        self.seq += 1
        self.ctl[ch.STOP_FAST_SEQ] = self.seq  # the loop's next poll sets its stop request
        c.target = self.seq
        c.read_at = time.monotonic()
        self.stops += 1
        self.waiting.append(c)

    def _refuse(self, c: _Conn, why: str) -> None:
        self.refused += 1
        self._answer(c, {"ok": False, "input_error": True, "message": why})

    def _answer(self, c: _Conn, rep: dict[str, Any]) -> None:
        if c.rid is not None:
            rep["id"] = c.rid
        try:
            c.sock.send(pr.dumps(rep))  # < 300 bytes into an empty socket buffer
            for _ in range(4):  # unread bytes at close would reset the connection before
                c.sock.recv(65536)  # the client reads its answer (a long line's rest)
        except OSError:
            pass
        self._close(c)

    def _close(self, c: _Conn) -> None:
        if c in self.waiting:
            self.waiting.remove(c)
        fd = c.sock.fileno()
        if fd >= 0:
            self.conns.pop(fd, None)
            try:
                self.sel.unregister(c.sock)
            except (KeyError, ValueError):
                pass
        try:
            c.sock.close()
        except OSError:
            pass


def set_priority(realtime: str, loop_priority: int) -> str:
    """The stop server's scheduling (see the module docstring); returns what it got."""
    if realtime != "off" and loop_priority > 1:
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(loop_priority - 1))
            return f"SCHED_FIFO {loop_priority - 1}"
        except (AttributeError, OSError):
            pass
    try:
        os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))  # not the parent's FIFO
    except (AttributeError, OSError):
        pass
    now = os.getpriority(os.PRIO_PROCESS, 0)
    for nice in range(-20, now):
        try:
            os.setpriority(os.PRIO_PROCESS, 0, nice)
            return f"nice {nice}"
        except OSError:
            continue
    return f"nice {now}"


def start(chan: ch.Channel, listener: socket.socket, realtime: str, priority: int) -> Any:
    """The stop server's process on ``listener`` (closed here: the child serves it)."""
    import subprocess

    from hofto_hw.runtime.realtime import cpus_beside_loop

    proc = subprocess.Popen(
        [sys.executable, "-m", "hofto_hw.control_plane.stop_server"],
        stdin=subprocess.PIPE,
        pass_fds=[listener.fileno()],
    )
    assert proc.stdin is not None
    cpus = cpus_beside_loop()  # the loop's own CPU stays the loop's
    proc.stdin.write(pickle.dumps((chan.name, chan.n, chan.k, listener.fileno(), realtime,
                                   int(priority), cpus)))  # fmt: skip
    proc.stdin.close()
    listener.close()
    return proc


def main() -> int:
    """The stop server's process: serves until the loop sets LOOP_DONE or its parent dies.
    SIGINT and SIGTERM are the loop's (a stop of the whole service still stops the arm
    through the loop, and stops sent meanwhile are still served)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    name, n, k, fd, realtime, priority, cpus = pickle.load(sys.stdin.buffer)
    sys.stdin.close()
    if cpus is not None:  # started from the pinned loop: off its CPU before anything else
        os.sched_setaffinity(0, cpus)
    chan = ch.Channel(n, k, name=name)
    server = StopServer(socket.socket(fileno=fd), chan)
    parse_stop(b'{"cmd": "stop", "id": 1}')  # the paths a stop takes, loaded before one comes
    pr.dumps({"ok": True, "message": "stop requested", "tick": 1, "server_ms": 0.1})
    gc.collect()
    gc.freeze()
    parent = os.getppid()
    got = set_priority(realtime, priority)
    chan.ctl[ch.STOP_PID] = os.getpid()
    if os.environ.get("HOFTO_HW_STOP_SERVER_VERBOSE"):
        print(f"hofto-hw stop server: {got}", file=sys.stderr)
    try:
        server.serve(lambda: bool(chan.ctl[ch.LOOP_DONE]) or os.getppid() != parent)
    finally:
        chan.close()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
