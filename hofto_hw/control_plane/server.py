"""The control-plane server: the control socket (selectors, non-blocking), the requests'
checks, planning, taught-path saving and the status, against a :class:`Channel`.

Every client is served by one selector loop without blocking the others: reads and writes
are non-blocking, a request line is at most ``protocol.MAX_LINE`` bytes (a longer one is
answered with one line and the connection closed), a line that does not complete within
``line_timeout`` is answered and closed (a client trickling bytes), at most ``max_clients``
connections are open (one more closes an idle one, or is answered "too many
clients" when none is idle: an operator's stop always gets in), a client that
does not read its replies is closed when ``MAX_PENDING_OUT`` bytes wait for it. A ``stop``
line is answered as soon as it is read (it writes the channel's stop word), never queued
behind anything; other lines are taken at most ``LINES_PER_TURN`` per connection and
``TURN_BUDGET`` in all per turn, round robin, so that one turn stays short whoever floods;
``status`` is built at most every ``STATUS_CACHE_S``.

Requests for the loop (reset, mode, play) go one at a time through the request ring and
are answered when the loop's reply record arrives; planning (ruckig moves, the taught
path's timing) runs in a forked planner process (:class:`Planner`, nice ``PLANNER_NICE``,
on the control plane's CPUs: off the loop's when it is pinned), which sends the plan in
chunks of ``PLAN_CHUNK`` rows as it samples them; the loop is told to play once the first
chunk is in the plan ring, and the rest is streamed ahead of it while it plays (a chunk is
read from the planner only when the ring has room for it: the planner waits, not the
loop; a row not there in time is the loop's "not yet", a ramp down at the plan's limits).
One client at a time holds motion and the enabling input (the first that asks; until it
disconnects or sends ``release``); another one's motion request is refused naming the
holder. The remote enabling input is a lease: ``enable on`` holds it for ``lease`` seconds
(``drag.enable_input.lease``) from now; it expires unless renewed, and the holder's
disconnect releases it at once.
"""

from __future__ import annotations

import collections
import os
import selectors
import socket
import struct
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from hofto_hw.control.joint_motion import DRAG, HOLD, MODE_NAMES, MOVE
from hofto_hw.control.path_timing import Limits
from hofto_hw.control_plane import channel as ch
from hofto_hw.control_plane import protocol as pr
from hofto_hw.errors import UserError
from hofto_hw.runtime import teach
from hofto_hw.runtime.axes import axes_of
from hofto_hw.runtime.timing import percentile_of, summarize
from hofto_hw.runtime.zero_offset import joint_index
from safety.stop import EVENT_NAMES, FAULT_NAMES, N_FAULTS

LINES_PER_TURN = 8
READ_CHUNK = 8192  # [bytes] read per connection per turn: a flood's turn stays short
TURN_BUDGET = 32  # request lines handled per turn over all connections
STATUS_CACHE_S = 0.02  # a status is built at most every 20 ms (a flood asks it back to back)
PLAN_CHUNK = 256  # rows per message from the planner (37 KB for 6 joints: within a pipe's
# 64 KB, so a message the server reads is whole in the pipe and never waits on the planner)
CHUNKS_PER_TURN = 16  # the plan ring (4096 rows) filled in one turn at the start
PLANNER_NICE = 5  # the planner's nice value: behind the control plane and its clients
RAMP_STEP_S = 0.02  # [s] between two intermediate payloads of a payload ramp
MAX_PENDING_OUT = 1 << 20
LOOP_ANSWER_TIMEOUT = 5.0  # [s] the loop answers a request within a few ticks
_MODE_CODE = {"hold": HOLD, "move": MOVE, "drag": DRAG}


@dataclass
class Conn:
    sock: socket.socket
    ident: int
    opened: float
    pid: int = 0
    name: str = ""
    inbuf: bytearray = field(default_factory=bytearray)
    outbuf: bytearray = field(default_factory=bytearray)
    partial_since: float = 0.0  # when the incomplete line in inbuf began (0: none)
    lines: collections.deque = field(default_factory=collections.deque)
    busy: bool = False  # a request of this connection is being answered
    closing: bool = False
    last: float = 0.0
    requests: int = 0  # request lines taken

    def who(self) -> str:
        name = f"{self.name!r} " if self.name else ""
        return f"client {name}(pid {self.pid}, connection {self.ident})"


@dataclass
class _Ramp:
    """A payload being ramped in: ``steps`` intermediate payloads from ``start`` to
    ``target`` over ``duration`` [s] from ``t0`` (monotonic); ``k`` sent so far."""

    conn: Any
    req: dict[str, Any]
    start: Any
    target: Any
    t0: float
    duration: float
    steps: int
    k: int = 0
    inflight: bool = False
    previous: Any = None  # the last step the loop took (None: start)

    def __post_init__(self) -> None:
        self.previous = self.start


@dataclass
class LoopJob:
    conn: Conn
    req: dict[str, Any]
    kind: int
    mode: int = 0
    arg: int = 0
    flag: int = 0
    value: Any = 0.0  # a float, or up to channel.VALUE_WORDS numbers
    seq: int = 0
    sent_at: float = 0.0
    done: Any = None  # callable(ok, text) -> reply dict, or None
    timeout: float = 5.0  # [s] the loop answers within (LOOP_ANSWER_TIMEOUT; homing: longer)


class ControlPlane:
    """See the module docstring. ``listener``: a bound, listening AF_UNIX socket.
    ``model``: the robot model (planning, TCP pose); ``cfg``: the SystemConfig."""

    def __init__(
        self,
        listener: socket.socket | None,
        chan: ch.Channel,
        cfg: Any,
        model: Any,
        *,
        observer_names: list[str],
        config_path: Path | str | None = None,
        log_path: str | None = None,
        recorder: dict[str, Any] | None = None,
        max_clients: int = 16,
        line_timeout: float = 2.0,
        idle_timeout: float = 3600.0,
    ) -> None:
        self.listener = listener
        self.chan = chan
        self.cfg = cfg
        self.model = model
        self.observer_names = list(observer_names)
        #: the service's config file (zero set rewrites it; None: nothing to rewrite)
        self.config_path = None if config_path is None else Path(config_path)
        bus = getattr(cfg, "bus", None)
        #: the zero offsets [counts] the loop runs with (zero set changes them)
        self.zero = [] if bus is None else [int(d.zero_offset) for d in bus.drives]
        self.rate_hz = float(cfg.loop.rate_hz)
        self.log_path = log_path
        self.recorder_info = recorder
        self._rec_block = None
        self.max_clients = int(max_clients)
        self.line_timeout = float(line_timeout)
        self.idle_timeout = float(idle_timeout)
        drag = getattr(cfg, "drag", None)
        self.lease_s = float(getattr(drag.enable_input, "lease", 0.25)) if drag else 0.25
        self.sel = selectors.DefaultSelector()
        if listener is not None:
            listener.setblocking(False)
            self.sel.register(listener, selectors.EVENT_READ, None)
        self.conns: dict[int, Conn] = {}
        self._next_ident = 1
        self.holder: Conn | None = None
        self.jobs: collections.deque[LoopJob] = collections.deque()
        self.inflight: LoopJob | None = None
        self._seq = 0
        self.events: collections.deque[dict[str, Any]] = collections.deque(maxlen=1024)
        self.events_total = 0
        # planning (a forked process: Planner) and the plan being streamed
        self._planner: Planner | None = None
        self._planner_for: tuple[Conn, dict[str, Any]] | None = None
        self._plan_accel: Any = None
        self.plan_id = 0
        self.plan_written = 0
        self.playback_info: dict[str, Any] | None = None
        # taught path being recorded
        self.recording: teach.Recording | None = None
        self.rec_waiters: list[tuple[Conn, dict[str, Any], float]] = []
        self.teach_info: dict[str, Any] | None = None
        self._p99_at = 0.0
        self._log_at = 0.0
        self._rr = 0
        self._status_at = -1.0
        self._status: dict[str, Any] | None = None
        self._log_watch: Any = None
        self._data = model.create_data()
        self.stop_answered = 0
        # the payload: the configured one until a client sets another (set_payload)
        from hofto_hw.errors import ModelError
        from hofto_hw.model.payload import LinkSwap, bare_link, payload_from_config

        held = cfg.safety.payload
        self.payload = {"mass": float(held.mass), "com": [float(v) for v in held.com]}
        self._held = payload_from_config(held)  # the last one sent to the loop
        self._ramp: _Ramp | None = None
        self._holding: Any = None
        try:
            self._bare_link = bare_link(model)
            self._payload_swap: LinkSwap | None = LinkSwap(model)
        except ModelError:  # the tool is not on a moving link: set_payload is refused
            self._payload_swap = None
        if self._payload_swap is not None and cfg.robot.rated_payload is not None:
            from hofto_hw.model.holding import HoldingTorque

            self._holding = HoldingTorque(model)  # ~0.1 s, once

    # ------------------------------------------------------------------ main loop

    def serve(self, done: Any = None, tick_s: float = 0.005) -> None:
        """Serve until ``done()`` is true or the loop has ended (LOOP_DONE)."""
        while not (done is not None and done()) and not self.chan.ctl[ch.LOOP_DONE]:
            # sockets wake the select at once; the loop's replies, a plan to stream, a taught
            # path to drain are polled: every tick_s while one is in progress, else 4x slower
            busy = self.inflight is not None or self._planner is not None
            busy = busy or self.recording is not None or self._ramp is not None
            self.turn(tick_s if busy else 4.0 * tick_s)
        self.finish()

    def turn(self, timeout: float) -> None:
        """One turn: socket I/O, stops first, other lines, the loop's replies, streaming."""
        now = time.monotonic()
        ready = self.sel.select(timeout)
        for key, _ in ready:  # new connections first: an operator's stop comes on one
            if key.data is None:
                for _ in range(8):  # a burst of connections: up to 8 a turn
                    if not self._accept(now):
                        break
        for key, mask in ready:
            if key.data is None or key.data == "planner":
                continue  # the planner's pipe is read in _planned, one message a turn
            c: Conn = key.data
            if c.closing:
                continue
            if mask & selectors.EVENT_READ:
                self._read(c, now)
            if mask & selectors.EVENT_WRITE and not c.closing:
                self._flush(c)
        now = time.monotonic()
        self._lines(now)
        self._loop_replies(now)
        self._ramp_step(now)
        self._planned()
        self._teach(now)
        self._drain_events()
        self._timeouts(now)
        if self.recorder_info and now >= self._log_at:
            self._log_at = now + 0.1
            self._watch_log()
        if now >= self._p99_at:
            self._p99_at = now + 1.0
            x = self.chan.extra
            self.chan.fctl[ch.WAKE_P99] = percentile_of(
                self.chan.wakeup_counts, 99.0, float(x[ch.X_WAKE_MAX])
            )
            self.chan.fctl[ch.COMP_P99] = percentile_of(
                self.chan.compute_counts, 99.0, float(x[ch.X_COMP_MAX])
            )
        self.chan.ctl[ch.CP_BEAT] += 1

    # ------------------------------------------------------------------ sockets

    def _accept(self, now: float) -> bool:
        """Accept one pending connection; False when none was pending."""
        try:
            sock, _ = self.listener.accept()  # type: ignore[union-attr]
        except (BlockingIOError, InterruptedError):
            return False
        except OSError:
            return False
        sock.setblocking(False)
        c = Conn(sock, self._next_ident, now, last=now)
        self._next_ident += 1
        try:
            cred = sock.getsockopt(socket.SOL_SOCKET, socket.SO_PEERCRED, struct.calcsize("3i"))
            c.pid = struct.unpack("3i", cred)[0]
        except OSError:
            pass
        if len(self.conns) >= self.max_clients and not self._evict_idle():
            self._full(c)
            return True
        self.conns[c.ident] = c
        self.sel.register(sock, selectors.EVENT_READ, c)
        self._read(c, now)  # its first line (a stop?) may be here already: no select round
        return True

    def _full(self, c: Conn) -> None:
        """No room for ``c`` (every connection busy): a stop already sent on it is still
        served; anything else is answered "too many clients" and the connection closed."""
        try:
            data = c.sock.recv(READ_CHUNK)
        except OSError:
            data = b""
        for raw in data.split(b"\n")[:-1]:
            if b'"stop"' in raw and self._stop_line(c, raw):
                break
        else:
            msg = f"too many clients ({self.max_clients}), none idle"
            c.outbuf += pr.dumps({"ok": False, "message": msg})
        try:
            c.sock.send(c.outbuf)
        except OSError:
            pass
        c.closing = True
        c.sock.close()

    def _evict_idle(self) -> bool:
        """At ``max_clients``: close an idle connection (not the holder, nothing in
        progress; one that never sent a request first, then the one idle longest), so that a
        new one (an operator's stop) is always served."""
        idle = [
            c for c in self.conns.values() if c is not self.holder and not c.busy and not c.lines
        ]
        if not idle:
            return False
        c = min(idle, key=lambda c: (c.requests > 0, c.last))  # silent ones first
        self._refuse_and_close(c, f"closed: {self.max_clients} clients, this one idle longest")
        return True

    def _read(self, c: Conn, now: float) -> None:
        try:
            data = c.sock.recv(READ_CHUNK)
        except (BlockingIOError, InterruptedError):
            return
        except OSError:
            self._close(c)
            return
        if not data:
            self._close(c)
            return
        c.last = now
        buf = c.inbuf
        buf += data
        while True:
            i = buf.find(b"\n")
            if i < 0:
                break
            raw = bytes(buf[:i])
            del buf[: i + 1]
            if b'"stop"' in raw and self._stop_line(c, raw):
                continue  # answered now, ahead of everything queued
            c.lines.append(raw)
        if buf and not c.partial_since:
            c.partial_since = now
        elif not buf:
            c.partial_since = 0.0
        if len(buf) > pr.MAX_LINE:
            self._refuse_and_close(c, f"request longer than {pr.MAX_LINE} bytes")
            return
        if len(c.lines) > 256:  # a flood: stop reading until its lines are handled
            self._interest(c)

    def _interest(self, c: Conn) -> None:
        if c.closing:
            return
        ev = 0
        if len(c.lines) <= 256:
            ev |= selectors.EVENT_READ
        if c.outbuf:
            ev |= selectors.EVENT_WRITE
        try:
            if ev:
                self.sel.modify(c.sock, ev, c)
            else:
                self.sel.modify(c.sock, selectors.EVENT_READ, c)
        except (KeyError, ValueError, OSError):
            pass

    def _send(self, c: Conn, reply: dict[str, Any], req: dict[str, Any] | None = None) -> None:
        if c.closing:
            return
        if req is not None and "id" in req:
            reply = {"id": req["id"], **reply}
        try:
            c.outbuf += pr.dumps(reply)
        except ValueError:  # a non-finite number in a reply: a bug; say so, never send NaN
            c.outbuf += pr.dumps({"ok": False, "message": "internal error: non-finite reply"})
        if len(c.outbuf) > MAX_PENDING_OUT:
            self._close(c)
            return
        self._flush(c)

    def _flush(self, c: Conn) -> None:
        if c.outbuf:
            try:
                n = c.sock.send(c.outbuf)
                del c.outbuf[:n]
            except (BlockingIOError, InterruptedError):
                pass
            except OSError:
                self._close(c)
                return
        self._interest(c)

    def _refuse_and_close(self, c: Conn, message: str) -> None:
        try:
            c.sock.send(pr.dumps({"ok": False, "input_error": True, "message": message}))
        except OSError:
            pass
        self._close(c)

    def _close(self, c: Conn) -> None:
        if c.closing:
            return
        c.closing = True
        try:
            self.sel.unregister(c.sock)
        except (KeyError, ValueError):
            pass
        c.sock.close()
        self.conns.pop(c.ident, None)
        if self.holder is c:
            self.holder = None
            self.chan.ctl[ch.LEASE_NS] = 0  # the holder is gone: its enabling input too

    def _timeouts(self, now: float) -> None:
        for c in list(self.conns.values()):
            if c.partial_since and now - c.partial_since > self.line_timeout:
                self._refuse_and_close(
                    c, f"request line not completed within {self.line_timeout:g} s"
                )
            elif not c.busy and not c.lines and now - c.last > self.idle_timeout:
                self._close(c)

    # ------------------------------------------------------------------ requests

    def _stop_line(self, c: Conn, raw: bytes) -> bool:
        """A line that may be a stop (it holds '"stop"'): handled as it arrives. True when
        it was one."""
        try:
            req = pr.parse_request(raw)
        except pr.ProtocolError:
            return False
        if req["cmd"] != "stop":
            return False
        self._stop(c, req)
        return True

    def _lines(self, now: float) -> None:
        """Queued lines (stops never queue: _read answers them as they arrive): up to
        LINES_PER_TURN per connection and TURN_BUDGET in all, starting with a different
        connection each turn, so one turn stays short whoever floods."""
        conns = list(self.conns.values())
        if not conns:
            return
        self._rr = (self._rr + 1) % len(conns)
        budget = TURN_BUDGET
        for c in conns[self._rr :] + conns[: self._rr]:
            n = 0
            while c.lines and not c.busy and not c.closing and n < LINES_PER_TURN and budget > 0:
                n += 1
                budget -= 1
                raw = c.lines.popleft()
                c.requests += 1
                try:
                    req = pr.parse_request(raw)
                except pr.ProtocolError as exc:
                    self._send(c, {"ok": False, "input_error": True, "message": str(exc)})
                    continue
                try:
                    self._handle(c, req, now)
                except UserError as exc:
                    self._send(c, {"ok": False, "input_error": True, "message": str(exc)}, req)
            if len(c.lines) <= 256:
                self._interest(c)

    def _stop(self, c: Conn, req: dict[str, Any]) -> None:
        self.chan.ctl[ch.STOP_SEQ] += 1
        self.chan.ctl[ch.LEASE_NS] = 0
        self._status = None
        self.stop_answered += 1
        self._send(c, {"ok": True, "message": "stop requested"}, req)

    def _holder_refusal(self, c: Conn) -> str:
        h = self.holder
        if h is None or h is c or h.closing:
            self.holder = c
            return ""
        return f"refused: motion and enabling are held by {h.who()}"

    def _handle(self, c: Conn, req: dict[str, Any], now: float) -> None:
        cmd = req["cmd"]
        if cmd in pr.MOTION:
            why = self._holder_refusal(c)
            if why:
                self._send(c, {"ok": False, "message": why}, req)
                return
        if cmd == "hello":
            c.name = str(req.get("name", ""))[:64]
            self._send(c, {"ok": True, **self.hello()}, req)
        elif cmd == "status":
            if self._status is None or now - self._status_at > STATUS_CACHE_S:
                self._status, self._status_at = self.status(), now
            self._send(c, {"ok": True, **self._status}, req)
        elif cmd == "state":
            self._send(c, {"ok": True, **self.state()}, req)
        elif cmd == "stream_info":
            self._send(c, {"ok": True, **self.stream_info()}, req)
        elif cmd == "events":
            since = int(req.get("since", 0))
            evs = [e for e in self.events if e["seq"] >= since]
            self._send(c, {"ok": True, "events": evs, "next": self.events_total}, req)
        elif cmd == "release":
            if self.holder is c:
                self.holder = None
                self.chan.ctl[ch.LEASE_NS] = 0
            self._send(c, {"ok": True, "message": "released"}, req)
        elif cmd == "reset":
            self._queue(LoopJob(c, req, ch.REQ_RESET))
        elif cmd == "enable":
            self._enable(c, req)
        elif cmd == "mode":
            self._mode(c, req)
        elif cmd == "cancel":
            self._queue(LoopJob(c, req, ch.REQ_MODE, mode=HOLD))
        elif cmd == "set_safety_profile":
            self._set_profile(c, req)
        elif cmd == "set_payload":
            self._set_payload(c, req)
        elif cmd in ("replay", "move_joints", "move_linear"):
            self._plan_request(c, req)
        elif cmd == "home":
            self._home(c, req)
        elif cmd == "zero_set":
            self._zero_set(c, req)
        else:  # pragma: no cover - protocol.COMMANDS and this table agree
            self._send(c, {"ok": False, "message": f"{cmd}: not served"}, req)

    # ------------------------------------------------------------------ profiles

    def _profiles(self) -> Any:
        return self.cfg.safety.profiles

    def active_profile(self, x: np.ndarray | None = None) -> tuple[str | None, dict | None]:
        """The loop's active safety profile: (name, content), (None, None) without any."""
        prof = self._profiles()
        if prof is None:
            return None, None
        if x is None:
            got = self.chan.read_state()
            x = None if got is None else got[1]
        names = prof.names()
        i = names.index(prof.active) if x is None else int(x[ch.X_PROFILE])
        name = names[i] if 0 <= i < len(names) else prof.active
        return name, prof.sets[name].model_dump()

    def _set_profile(self, c: Conn, req: dict[str, Any]) -> None:
        prof = self._profiles()
        name = req["name"]
        if prof is None:
            raise UserError("set_safety_profile: the config has no safety.profiles")
        if name not in prof.sets:
            raise UserError(
                f"set_safety_profile: {name!r} is not a profile ({', '.join(prof.names())})"
            )
        content = prof.sets[name].model_dump()

        def done(ok: bool, text: str) -> dict[str, Any]:
            if not ok:
                return {"ok": False, "message": text}
            print(f"hofto-hw run: safety profile {name} active: {content}", flush=True)
            return {"ok": True, "message": f"safety profile {name} active", "profile": content}

        p = prof.sets[name]
        self._queue(
            LoopJob(
                c, req, ch.REQ_PROFILE, arg=prof.names().index(name),
                value=[p.collision_scale, *p.drag_factors()], done=done,
            )
        )  # fmt: skip

    # ------------------------------------------------------------------ payload

    def _set_payload(self, c: Conn, req: dict[str, Any]) -> None:
        """Checked here (finite, within ``robot.rated_payload``, its holding torque within
        the joints' torque limits), then ramped in (:meth:`_ramp_step`): the tool link's
        inertia with each intermediate payload computed here (hofto_hw.model.payload),
        swapped in by the loop at standstill. A new one supersedes a ramp in progress (its
        client is answered so), from the payload the loop was last sent."""
        from hofto_hw.model.payload import Payload

        rated = self.cfg.robot.rated_payload
        if rated is None:
            raise UserError(
                "set_payload: the config has no robot.rated_payload (the load the arm is "
                "rated for): the payload is safety.payload"
            )
        mass = req["mass"]
        if not np.isfinite(mass) or not 0.0 <= mass <= rated.mass:
            raise UserError(
                f"set_payload.mass: {mass} kg is not within [0, {rated.mass:g}] kg "
                "(robot.rated_payload.mass)"
            )
        try:
            com = pr.numbers(req["com"], "set_payload.com", 3)
        except pr.ProtocolError as exc:
            raise UserError(str(exc)) from None
        dist = float(np.linalg.norm(com))
        if dist > rated.com_max:
            raise UserError(
                f"set_payload.com: {dist:.4g} m from the tool frame, more than "
                f"robot.rated_payload.com_max = {rated.com_max:g} m"
            )
        if self._payload_swap is None:
            raise UserError(f"set_payload: {self.model.name}'s tool frame is not on a moving link")
        new = Payload(float(mass), (com[0], com[1], com[2]))
        got = self.chan.read_state()
        if got is None:
            self._send(c, {"ok": False, "message": "the loop has not started"}, req)
            return
        self._check_holding(np.array(got[0]["q"], dtype=float), new, rated.holding_fraction)
        old = self._ramp
        if old is not None:  # superseded: its client hears so; this one starts where it is
            self._ramp = None
            msg = f"set_payload: superseded by a new one ({new.mass:g} kg) before it was active"
            self._send(old.conn, {"ok": False, "message": msg}, old.req)
        steps = max(1, int(np.ceil(rated.ramp_s / RAMP_STEP_S)))
        self._ramp = _Ramp(c, req, self._held, new, time.monotonic(), rated.ramp_s, steps)
        self._ramp_step(time.monotonic())

    def _check_holding(self, q: np.ndarray, new: Any, fraction: float) -> None:
        """Refuse (one line naming the joint, the torque and the limit) a payload whose
        holding torque exceeds ``fraction`` of a joint's torque limit at the current pose
        ``q`` or at the worst pose the joint limits allow (hofto_hw.model.holding)."""
        if self._holding is None:
            return
        why = self._holding.refusal(q, new, fraction)
        if why:
            raise UserError(f"set_payload: {new.mass:g} kg at com {list(new.com)} m: {why}")

    def _ramp_step(self, now: float) -> None:
        """Send the ramp's next intermediate payload when it is due (step k of N at k/N of
        ``ramp_s``, the first at once) and the previous one was answered."""
        from hofto_hw.model.payload import blend, link_numbers

        r = self._ramp
        if r is None or r.inflight or now < r.t0 + r.duration * r.k / r.steps:
            return
        r.k += 1
        p = blend(r.start, r.target, r.k / r.steps)
        link = link_numbers(self.model, self._bare_link, p)
        r.inflight = True
        self._held = p

        def done(ok: bool, text: str, r=r, p=p, link=link) -> dict[str, Any] | None:
            r.inflight = False
            if ok:
                self._applied(p, link)
            elif self._held is p:  # refused (the arm moved): the loop holds the one before
                self._held = r.previous
            if self._ramp is not r:
                return None  # superseded: its client was answered then
            r.previous = p if ok else r.previous
            if not ok:
                self._ramp = None
                held = self.payload["mass"]
                return {"ok": False, "message": f"{text} (the payload held is {held:g} kg)"}
            if r.k < r.steps:
                return None  # the client is answered at the ramp's end
            self._ramp = None
            msg = (
                f"payload {p.mass:g} kg at com {list(r.target.com)} m (tool frame) active"
                f" (ramped in over {r.duration:g} s)"
            )
            print(f"hofto-hw run: {msg}", flush=True)
            return {"ok": True, "message": msg, "payload": dict(self.payload)}

        value = [p.mass, *p.com, *link]
        self._queue(LoopJob(r.conn, r.req, ch.REQ_PAYLOAD, value=value, done=done))

    def _applied(self, p: Any, link: np.ndarray) -> None:
        """The loop took payload ``p``: the plans' model (torque checks) carries it too."""
        swap = self._payload_swap
        assert swap is not None
        if swap.model.payload != p:  # (the loop's own model in InProcessControl)
            np.copyto(swap.values, link)
            swap.apply(p)
        self.payload = {"mass": p.mass, "com": list(p.com)}

    def _enable(self, c: Conn, req: dict[str, Any]) -> None:
        got = self.chan.read_state()
        src = -1 if got is None else int(got[1][ch.X_ENABLE_SOURCE])
        name = ch.SOURCES[src] if 0 <= src < len(ch.SOURCES) else "?"
        if name != "socket":
            msg = f"drag.enable_input.source is {name!r}, not 'socket'"
            self._send(c, {"ok": False, "message": msg}, req)
            return
        if req["on"]:
            self.chan.ctl[ch.LEASE_NS] = time.monotonic_ns() + int(self.lease_s * 1e9)
            msg = f"enabling input on for {self.lease_s:g} s (renew to hold it)"
        else:
            self.chan.ctl[ch.LEASE_NS] = 0
            msg = "enabling input off"
        self._send(c, {"ok": True, "message": msg, "lease_s": self.lease_s}, req)

    def _mode(self, c: Conn, req: dict[str, Any]) -> None:
        what = req["mode"]
        rec_file = req.get("record")
        if (rec_file is not None or req.get("force")) and what != "drag":
            raise UserError(f"mode {what}: record/force only with mode drag")
        got = self.chan.read_state()
        if got is not None and got[1][ch.X_STOPPING]:
            self._send(c, {"ok": False, "message": "a stop is latched: reset first"}, req)
            return
        if self._ramp is not None and what != "hold":
            msg = "refused: a payload is being ramped in (robot.rated_payload.ramp_s)"
            self._send(c, {"ok": False, "message": msg}, req)
            return
        if what == "drag":
            rec = None
            if rec_file is not None:
                file = teach.check_output(rec_file, bool(req.get("force", False)))
                cap = round(self.cfg.motion.record_seconds * self.rate_hz)
                rec = teach.Recording(file, bool(req.get("force", False)), self.model, cap)
                self._save_recording(0.0)  # a finished earlier one first
            drained = self.chan.taught.drain()  # leftovers of an earlier recording
            del drained

            def done(ok: bool, text: str, rec=rec) -> dict[str, Any]:
                if not ok:
                    return {"ok": False, "message": text}
                if rec is not None:
                    self.recording = rec
                where = f", recording the taught path to {rec.file}" if rec is not None else ""
                return {"ok": True, "message": f"mode drag{where}"}

            self._queue(
                LoopJob(c, req, ch.REQ_MODE, mode=DRAG, flag=int(rec is not None), done=done)
            )
            return

        def after(ok: bool, text: str) -> dict[str, Any] | None:
            if ok and what == "hold" and self.recording is not None:
                self.rec_waiters.append((c, {"ok": True, "message": text}, time.monotonic() + 2.0))
                return None  # answered when the taught path is saved
            return {"ok": ok, "message": text}

        self._queue(LoopJob(c, req, ch.REQ_MODE, mode=_MODE_CODE[what], done=after))

    # ------------------------------------------------------------------ commissioning

    def _joint(self, v: str | int, what: str) -> int:
        """A joint by name or 1-based number -> its index (UserError naming the choices)."""
        names = list(self.model.joint_names)
        if isinstance(v, int) and not isinstance(v, bool):
            v = str(v)
        return joint_index(str(v), names, what)

    def _at_rest_refusal(self, what: str) -> str:
        """What the state slot says against ``what`` now ("" when nothing); the loop checks
        again when it takes the request."""
        got = self.chan.read_state()
        if got is None:
            return f"{what} refused: the loop has not started"
        rec, x = got
        if int(rec["faults"]) or x[ch.X_STOPPING]:
            names = ", ".join(self._faults(int(rec["faults"]))) or "a stop"
            return f"{what} refused: {names} latched: reset first"
        if x[ch.X_MOVING] or float(np.abs(rec["qd"]).max()) >= 0.01:
            return f"{what} refused: the arm is moving; hold at rest first"
        return ""

    def _home(self, c: Conn, req: dict[str, Any]) -> None:
        """CiA 402 homing of the named joints (default: every joint with ``homing:``) by
        the loop, one after the other in axis order, back to the loop's mode."""
        bus = self.cfg.bus
        if bus is None:
            raise UserError("home: the config has no bus: section: no drive to home")
        names = list(self.model.joint_names)
        if req.get("joints"):
            axes = sorted({self._joint(v, "home") for v in req["joints"]})
            for j in axes:
                if bus.drives[j].homing is None:
                    raise UserError(
                        f"home: bus.drives[{j}].homing: none: {names[j]} has an absolute "
                        "encoder, nothing to home"
                    )
        else:
            axes = [i for i, d in enumerate(bus.drives) if d.homing is not None]
        if not axes:
            msg = "every axis has homing: none (absolute encoders): nothing to home"
            self._send(c, {"ok": True, "message": msg}, req)
            return
        why = self._at_rest_refusal("home")
        if why:
            self._send(c, {"ok": False, "message": why}, req)
            return
        seconds = sum(bus.drives[j].homing.timeout for j in axes)  # type: ignore[union-attr]
        self._queue(
            LoopJob(
                c, req, ch.REQ_HOME, arg=sum(1 << j for j in axes),
                timeout=LOOP_ANSWER_TIMEOUT + 2.0 * seconds,
            )
        )  # fmt: skip

    def _zero_set(self, c: Conn, req: dict[str, Any]) -> None:
        """Rewrite a joint's zero offset so its measured position reads ``at`` [rad]: the
        edit is prepared and checked here, the loop takes the new offset at a tick boundary
        (refused while moving or latched), then the config is replaced (backup kept) and
        the change logged, here: no file is touched in the loop's process."""
        from hofto_hw.config import load_config
        from hofto_hw.runtime import zero_offset as zo

        bus = self.cfg.bus
        if bus is None:
            raise UserError("zero set: the config has no bus: section: no zero offset to set")
        path = self.config_path
        if path is None:
            raise UserError("zero set: this service was started without a config file")
        j = self._joint(req["joint"], "zero set")
        at = zo.parse_angle(req["at"])
        name = self.model.joint_names[j]
        drive = bus.drives[j]
        if drive.homing is not None:
            msg = (
                f"zero set refused: {name} is homed (homing: method {drive.homing.method}): its "
                "zero comes from homing; change homing.offset"
            )
            self._send(c, {"ok": False, "message": msg}, req)
            return
        why = self._at_rest_refusal("zero set")
        if why:
            self._send(c, {"ok": False, "message": why}, req)
            return
        old = self.zero[j]
        disk = load_config(path)
        if disk.bus is None or disk.bus.drives[j].zero_offset != old:
            have = None if disk.bus is None else disk.bus.drives[j].zero_offset
            raise UserError(
                f"{path}: bus.drives[{j}].zero_offset is {have}, the service runs with {old}: "
                "the file changed since it started; restart the service first"
            )
        got = self.chan.read_state()
        assert got is not None  # _at_rest_refusal read one
        q = float(got[0]["q"][j])
        new = zo.new_zero_offset(drive, old, q, at)
        text = zo.prepare_edit(path, disk, j, new)
        log_folder = self._log_dir()

        def applied(ok: bool, reason: str) -> dict[str, Any] | None:
            if not ok:
                return {"ok": False, "message": reason}
            what = (
                f"{name} zero_offset {old} -> {new} counts (position {q:.6f} rad set to "
                f"{at:.6f} rad, through the service)"
            )
            try:
                line = zo.commit_edit(path, text, log_folder, what)
            except OSError as exc:  # the loop runs with the new offset: put the old one back
                err = f"zero set: {path}: not written ({exc.strerror})"

                def back(ok2: bool, reason2: str) -> dict[str, Any]:
                    tail = (
                        "; the old offset is back" if ok2 else f"; restoring it failed: {reason2}"
                    )
                    return {"ok": False, "message": err + tail}

                self._queue(LoopJob(c, req, ch.REQ_ZERO, arg=j, value=(old, new), done=back))
                return None
            self.zero[j] = new
            self._shift_stored_position(log_folder, name, new, old, drive)
            print(f"hofto-hw run: zero set: {line}", flush=True)
            return {"ok": True, "message": line, "zero_offset": new, "previous": old}

        self._queue(LoopJob(c, req, ch.REQ_ZERO, arg=j, value=(new, old), done=applied))

    def _log_dir(self) -> Path:
        from hofto_hw.commands.run import _log_dir

        assert self.config_path is not None
        return _log_dir(self.cfg, self.config_path)

    def _shift_stored_position(
        self, folder: Path, name: str, new: int, old: int, drive: Any
    ) -> None:
        """The positions file of the last clean shutdown read with the new offset (so a
        start-up after a crash compares like with like); absent: nothing to do."""
        from hofto_hw.runtime.positions import load_positions, save_positions, state_path

        path = state_path(folder)
        try:
            last = load_positions(path)
        except UserError:
            return
        if last is None or name not in last.joints:
            return
        k = last.joints.index(name)
        if last.zero_offsets[k] != old:
            return
        from hofto_hw.runtime.zero_offset import shift_of

        last.positions[k] += shift_of(drive, old, new)
        last.zero_offsets[k] = new
        try:
            save_positions(path, last)
        except OSError:
            pass

    # ------------------------------------------------------------------ the loop's ring

    def _queue(self, job: LoopJob) -> None:
        job.conn.busy = True
        self.jobs.append(job)
        self._send_next()

    def _send_next(self) -> None:
        if self.inflight is not None or not self.jobs:
            return
        job = self.jobs.popleft()
        if job.conn.closing and job.kind not in (ch.REQ_PLAY, ch.REQ_PAYLOAD):  # a payload
            # ramp's steps go on without their client: the loop holds a payload it was sent
            self._send_next()
            return
        self._seq += 1
        job.seq = self._seq
        r = np.zeros((), ch.REQUEST_DTYPE)
        r["seq"], r["kind"], r["mode"] = job.seq, job.kind, job.mode
        r["arg"], r["flag"] = job.arg, job.flag
        v = np.atleast_1d(np.asarray(job.value, dtype=float))
        r["value"][: v.size] = v
        if not self.chan.requests.push(r):
            self._answer(job, {"ok": False, "message": "the loop's request ring is full"})
            self._send_next()
            return
        job.sent_at = time.monotonic()
        self.inflight = job

    def _answer(self, job: LoopJob, reply: dict[str, Any] | None) -> None:
        job.conn.busy = False
        self._status = None  # the loop acted: the next status is built anew
        if reply is not None:
            self._send(job.conn, reply, job.req)

    def _loop_replies(self, now: float) -> None:
        for rep in self.chan.replies.drain():
            job = self.inflight
            if job is None or int(rep["seq"]) != job.seq:
                continue
            self.inflight = None
            ok = bool(rep["code"])
            text = bytes(rep["text"]).decode("utf-8", "replace")
            reply = job.done(ok, text) if job.done else {"ok": ok, "message": text}
            self._answer(job, reply)
        job = self.inflight
        if job is not None and now - job.sent_at > job.timeout:
            self.inflight = None
            self._answer(job, {"ok": False, "message": "the loop did not answer the request"})
        self._send_next()

    # ------------------------------------------------------------------ planning

    def _plan_request(self, c: Conn, req: dict[str, Any]) -> None:
        got = self.chan.read_state()
        if got is None:
            self._send(c, {"ok": False, "message": "the loop has not started"}, req)
            return
        rec, x = got
        if x[ch.X_STOPPING]:
            self._send(c, {"ok": False, "message": "a stop is latched: reset first"}, req)
            return
        if self._ramp is not None:
            msg = "refused: a payload is being ramped in (robot.rated_payload.ramp_s)"
            self._send(c, {"ok": False, "message": msg}, req)
            return
        mode = int(rec["mode"])
        if mode != HOLD:
            name = MODE_NAMES.get(mode, "?")
            msg = f"refused: the arm is in mode {name}: mode hold first"
            self._send(c, {"ok": False, "message": msg}, req)
            return
        if self._planner is not None:
            if not self._planner.playing:
                msg = "refused: another plan is being made"
                self._send(c, {"ok": False, "message": msg}, req)
                return
            self._end_planner()  # its plan was played (the arm holds again): the rest unused
        q_now = np.array(rec["q_cmd"], dtype=float)
        limits = teach.motion_limits(self.cfg, self.model)
        speed = float(req.get("speed", 1.0))
        acc = float(req.get("acceleration", 1.0))
        for key, v in (("speed", speed), ("acceleration", acc)):
            if not 0.0 < v <= 1.0:
                raise UserError(f"{req['cmd']}.{key}: {v} is not a fraction of the limit in (0, 1]")
        _, prof = self.active_profile(x)
        if prof is not None:  # the active safety profile's fraction of the motion limits
            speed *= prof["speed_scale"]
            acc *= prof["speed_scale"]
        limits = Limits(limits.velocity * speed, limits.acceleration * acc, limits.jerk * acc)
        cmd = req["cmd"]
        if cmd == "move_joints":
            q = self._joint_target(req["q"])
            teach.check_target(q, self.model)  # before any thread: one line at once
        elif cmd == "move_linear":
            q = np.array(pr.numbers(req["pose"], "move_linear.pose", 6))  # the target pose
        c.busy = True
        dt = 1.0 / self.rate_hz
        target = q if cmd in ("move_joints", "move_linear") else None
        self._planner = Planner(cmd, req.get("file"), target, q_now, self.model, limits, dt)
        self._planner_for = (c, req)
        self._plan_accel = limits.acceleration
        self.sel.register(self._planner.conn, selectors.EVENT_READ, "planner")

    def _joint_target(self, values: list[Any]) -> np.ndarray:
        """move_joints.q -> (n,) [rad]; one line naming the joint for a value that is not a
        finite number (a client may send "nan"/"inf" as words: JSON has no NaN)."""
        model = self.model
        if len(values) != model.n:
            raise UserError(f"move_joints: {len(values)} values, {model.name} has {model.n} joints")
        out = np.zeros(model.n)
        for j, v in enumerate(values):
            name = model.joint_names[j]
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v):
                raise UserError(f"move_joints: {name}: {str(v)[:40]} is not a finite number")
            out[j] = v
        return out

    def _planned(self) -> None:
        """The planner's messages: its head (or its one-line refusal), then its chunks while
        the plan ring has room for them; the loop is told to play after the first."""
        pl = self._planner
        if pl is None:
            return
        if pl.head is None:
            if not pl.step():
                return
            if pl.head is None:  # refused or died before planning anything
                self._end_planner()
                c, req = self._planner_for  # type: ignore[misc]
                c.busy = False
                self._send(c, {"ok": False, "input_error": True, "message": pl.error}, req)
                return
            self._begin_plan(pl.head)
        ctl = self.chan.ctl
        for _ in range(CHUNKS_PER_TURN):
            tail = int(ctl[ch.PLAN_TAIL]) if int(ctl[ch.PLAN_TAIL_ID]) == self.plan_id else 0
            if self.plan_written + PLAN_CHUNK > tail + ch.PLAN_CAP or not pl.step():
                break
            if pl.chunk is not None:
                self._write_rows(*pl.chunk)
                pl.chunk = None
                if not pl.play_queued:
                    pl.play_queued = True
                    self._queue_play(pl)
            if pl.ended:
                break
        if pl.ended or pl.error:
            if pl.error and pl.play_queued:  # the loop ramps down where the rows end
                print(f"hofto-hw run: {pl.error}; the plan ends early", flush=True)
            elif pl.error:
                c, req = self._planner_for  # type: ignore[misc]
                c.busy = False
                self._send(c, {"ok": False, "message": pl.error}, req)
            self._end_planner()

    def _begin_plan(self, head: dict[str, Any]) -> None:
        """A new plan in the ring: no row yet (PLAN_HEAD 0), its first row, limits, length."""
        ctl = self.chan.ctl
        self.plan_id += 1
        ctl[ch.PLAN_HEAD] = 0
        self.chan.plan_start[:] = head["q0"]
        self.chan.plan_accel[:] = self._plan_accel
        ctl[ch.PLAN_ROWS] = head["rows"]
        self.plan_written = 0
        ctl[ch.PLAN_ID] = self.plan_id

    def _write_rows(self, i0: int, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray) -> None:
        """Rows i0 .. i0 + len(q) - 1 into the ring, then published (PLAN_HEAD)."""
        mask = ch.PLAN_CAP - 1
        w, end, o = i0, i0 + q.shape[0], 0
        while w < end:
            s = w & mask
            m = min(end - w, ch.PLAN_CAP - s)
            self.chan.plan_q[s : s + m] = q[o : o + m]
            self.chan.plan_qd[s : s + m] = qd[o : o + m]
            self.chan.plan_qdd[s : s + m] = qdd[o : o + m]
            w += m
            o += m
        self.plan_written = end
        self.chan.ctl[ch.PLAN_HEAD] = end  # published after the rows

    def _queue_play(self, pl: Planner) -> None:
        c, req = self._planner_for  # type: ignore[misc]
        h = pl.head
        assert h is not None
        arg = req.get("file", "")
        plan_id = self.plan_id

        def done(ok: bool, text: str) -> dict[str, Any]:
            if not ok:
                if self._planner is pl:
                    self._end_planner()
                return {"ok": False, "message": text}
            pl.playing = True
            duration = h["rows"] * h["dt"]
            self.playback_info = {
                "kind": h["kind"],
                "file": None if h["file"] is None else str(h["file"]),
                "rows": int(h["rows"]),
                "duration_s": round(duration, 3),
                "plan_id": plan_id,
            }
            if h["kind"] == "replay":
                to_start = h["segments"][1] * h["dt"]
                text = (
                    f"replaying {arg}: {to_start:.2f} s to its start, then "
                    f"{duration - to_start:.2f} s along it (time scale {h['scale']:.2f})"
                )
            elif h["kind"] == "linear":
                text = f"moving the tool along a line in {duration:.2f} s"
            else:
                text = f"moving to the joint target in {duration:.2f} s"
            return {"ok": True, "message": text, "duration_s": round(duration, 3)}

        c.busy = False
        self._queue(LoopJob(c, req, ch.REQ_PLAY, mode=h["mode"], arg=plan_id, done=done))

    def _end_planner(self) -> None:
        """Stop reading the planner (done, refused, or its plan no longer played)."""
        pl = self._planner
        if pl is None:
            return
        self._planner = None
        try:
            self.sel.unregister(pl.conn)
        except (KeyError, ValueError):
            pass
        pl.close()

    # ------------------------------------------------------------------ teach

    def _teach(self, now: float) -> None:
        rec = self.recording
        if rec is not None:
            rows = self.chan.taught.drain()
            for r in rows:
                rec.recorder.push(float(r["t"]), r["q"])
        self._save_recording(now)
        if self.rec_waiters and self.recording is None:
            for c, reply, _ in self.rec_waiters:
                if self.teach_info and self.teach_info.get("message"):
                    reply = {
                        **reply,
                        "message": f"{reply['message']}; {self.teach_info['message']}",
                    }
                c.busy = False
                self._send(c, reply)
            self.rec_waiters = []
        for c, reply, until in list(self.rec_waiters):
            if now > until:
                self.rec_waiters.remove((c, reply, until))
                c.busy = False
                self._send(c, reply)

    def _save_recording(self, now: float, at_end: bool = False) -> str:
        rec = self.recording
        if rec is None:
            return ""
        got = self.chan.read_state()
        state = teach.FINISHED if got is None else int(got[1][ch.X_TEACH_STATE])
        if state < teach.FINISHED and not at_end:
            rec.state = state
            return ""
        for r in self.chan.taught.drain():
            rec.recorder.push(float(r["t"]), r["q"])
        rec.state = teach.FINISHED
        msg = rec.save()
        self.teach_info = rec.status()
        self.recording = None
        print(f"hofto-hw run: {msg}", flush=True)
        return msg

    # ------------------------------------------------------------------ events

    def _drain_events(self) -> None:
        for e in self.chan.events.drain():
            kind = int(e["kind"])
            self.events.append(
                {
                    "seq": self.events_total,
                    "t": float(e["t"]),
                    "tick": int(e["tick"]),
                    "kind": EVENT_NAMES.get(kind, f"kind {kind}"),
                    "joint": int(e["joint"]),
                    "category": int(e["category"]),
                    "value": float(e["value"]) if np.isfinite(e["value"]) else None,
                }
            )
            self.events_total += 1

    # ------------------------------------------------------------------ answers

    def hello(self) -> dict[str, Any]:
        return {
            "robot": self.model.name,
            "joints": list(self.model.joint_names),
            "observers": self.observer_names,
            "rate_hz": self.rate_hz,
            "lease_s": self.lease_s,
            "protocol": 1,
        }

    def stream_info(self) -> dict[str, Any]:
        info = self.recorder_info
        if not info:
            return {"shm": None, "message": "this run keeps no flight recorder (--no-log)"}
        return {**info, "n": self.model.n, "k": len(self.observer_names)}

    def _faults(self, mask: int) -> list[str]:
        return [FAULT_NAMES[f] for f in range(N_FAULTS) if mask & (1 << f)]

    def status(self) -> dict[str, Any]:
        got = self.chan.read_state()
        if got is None:
            return {"state": "starting", "mode": "?", "category": -1, "faults": [],
                    "persisting": [], "ticks": 0, "overruns": 0,
                    "timing_us": {"compute": summarize(self.chan.compute_counts, 0.0),
                                  "wakeup": summarize(self.chan.wakeup_counts, 0.0)},
                    "log": self.log_path, "recorder": self._recorder_status(),
                    "teach": self.teach_info, "playback": None}  # fmt: skip
        rec, x = got
        if x[ch.X_EXIT]:
            state = "stopping"
        elif x[ch.X_STOPPING]:
            state = "stopped"
        elif x[ch.X_ENABLING]:
            state = "enabling"
        else:
            state = "running"
        latched = int(rec["faults"])
        cat = int(x[ch.X_CATEGORY])
        return {
            "state": state,
            "mode": MODE_NAMES.get(int(rec["mode"]), "?"),
            "category": cat,
            "faults": self._faults(latched),
            "persisting": self._faults(latched & int(x[ch.X_ACTIVE])),
            "ticks": int(x[ch.X_LOOP_TICKS]),
            "overruns": int(x[ch.X_OVERRUNS]),
            "timing_us": {
                "compute": summarize(self.chan.compute_counts.copy(), float(x[ch.X_COMP_MAX])),
                "wakeup": summarize(self.chan.wakeup_counts.copy(), float(x[ch.X_WAKE_MAX])),
            },
            "log": self.log_path,
            "recorder": self._recorder_status(),
            "teach": self._teach_status(x),
            "playback": self._playback_status(x),
            "holder": None if self.holder is None else self.holder.who(),
            "profile": self._profile_status(x),
            "payload": dict(self.payload),
            "acceleration": _acceleration(int(x[ch.X_ACCEL])),
            "axes": self._axes(x),
        }

    def _axes(self, x: np.ndarray) -> list[dict[str, Any]]:
        """Per axis: name, safe torque off (bool), holding brake (closed/open/None)."""
        n = self.chan.n
        return axes_of(
            list(self.model.joint_names), x[ch.X_WORDS : ch.X_WORDS + n], x[ch.X_WORDS + n :]
        )

    def _profile_status(self, x: np.ndarray) -> dict[str, Any] | None:
        name, content = self.active_profile(x)
        return None if name is None else {"name": name, **(content or {})}

    def _teach_status(self, x: np.ndarray) -> dict[str, Any] | None:
        rec = self.recording
        if rec is None:
            return self.teach_info
        return {
            "file": str(rec.file),
            "state": teach.STATE_NAMES.get(int(x[ch.X_TEACH_STATE]), "?"),
            "samples": int(x[ch.X_TEACH_SAMPLES]),
            "message": "",
        }

    def _playback_status(self, x: np.ndarray) -> dict[str, Any] | None:
        info = self.playback_info
        if info is None:
            return None
        k = int(x[ch.X_PLAN_K]) if int(x[ch.X_PLAN_ID]) == info["plan_id"] else 0
        done = bool(x[ch.X_PLAN_DONE]) and int(x[ch.X_PLAN_ID]) == info["plan_id"]
        return {
            "kind": info["kind"],
            "file": info["file"],
            "progress": round(min(1.0, (k + 1) / info["rows"]), 4),
            "completed": done,
            "duration_s": info["duration_s"],
        }

    def _watch_log(self) -> None:
        """The flight recorder's health as a safety input (runtime/log_watch.py's check,
        here instead of a thread of the loop's process): the channel's LOG_* words."""
        from types import SimpleNamespace

        from hofto_hw.runtime.log_watch import LogWatch

        chan = self.chan

        class _Words:
            def __setattr__(self, key: str, value: Any) -> None:
                if key == "log_failure":
                    chan.ctl[ch.LOG_FAILING] = 1 if value else 0
                elif key == "log_failure_value":
                    chan.ctl[ch.LOG_LOST] = int(value)

        def health() -> Any:
            st = self._recorder_status()
            if st is None:
                raise RuntimeError("no recorder")
            return SimpleNamespace(
                writer_alive=st["writer_alive"],
                disk_failing=st["failing"],
                dropped=st["dropped"],
                records_lost=st["records_lost"],
            )

        if self._log_watch is None:
            self._log_watch = LogWatch(SimpleNamespace(health=health), _Words())
        try:
            self._log_watch.check()
        except RuntimeError:
            pass

    def _recorder_status(self) -> dict[str, Any] | None:
        info = self.recorder_info
        if not info:
            return None
        from hofto_hw.recording import shared as sh
        from hofto_hw.recording.record import tick_dtype

        try:
            if self._rec_block is None:
                caps = sh.Capacities(*info["caps"])
                self._rec_block = sh.SharedBlock(
                    tick_dtype(self.model.n, len(self.observer_names)), caps, name=info["shm"]
                )
            b = self._rec_block
            c = b.control
            pid = int(c[sh.PID])
        except (OSError, ValueError, KeyError):
            return None
        alive = _alive(pid)
        return {
            "writer_alive": alive,
            "state": sh.STATE_NAMES.get(int(c[sh.STATE]), "?"),
            "records_written": int(c[sh.RECORDS]),
            "records_flushed": int(c[sh.FLUSHED]),
            "dropped": b.ticks.dropped + b.events.dropped + b.diags.dropped,
            "records_lost": int(c[sh.LOST]),
            "write_errors": int(c[sh.ERRORS]),
            "pending": b.ticks.pending(),
            "failing": bool(c[sh.FAILING]),
        }

    def state(self) -> dict[str, Any]:
        """The typed snapshot of ``Robot.state()`` (SI units)."""
        got = self.chan.read_state()
        if got is None:
            raise UserError("state: the loop has not run a tick yet")
        rec, x = got
        q = rec["q"]
        pos, rot = self._data.tool_pose(q)
        src = int(x[ch.X_ENABLE_SOURCE])
        lease_left = 0.0
        if int(self.chan.ctl[ch.LEASE_NS]):
            lease_left = max(0.0, (int(self.chan.ctl[ch.LEASE_NS]) - time.monotonic_ns()) * 1e-9)
        latched = int(rec["faults"])

        def finite(a: np.ndarray) -> list[Any]:
            return [float(v) if np.isfinite(v) else None for v in np.ravel(a)]

        return {
            "t": float(rec["t"]),
            "tick": int(rec["tick"]),
            "mode": MODE_NAMES.get(int(rec["mode"]), "?"),
            "faults": self._faults(latched),
            "category": int(x[ch.X_CATEGORY]),
            "stop_requested": bool(x[ch.X_STOP_REQUESTED]),
            "moving": bool(x[ch.X_MOVING]),
            "q": finite(q),
            "qd": finite(rec["qd"]),
            "tau": finite(rec["tau"]),
            "q_cmd": finite(rec["q_cmd"]),
            "tau_ext": {
                name: finite(rec["tau_ext"][i]) for i, name in enumerate(self.observer_names)
            },
            "wrench": finite(rec["wrench"]),
            "tcp_position": finite(pos),
            "tcp_rotation": [finite(row) for row in np.asarray(rot)],
            "enabling": {
                "source": ch.SOURCES[src] if 0 <= src < len(ch.SOURCES) else "?",
                "pressed": bool(x[ch.X_PRESSED]),
                "drag_active": bool(x[ch.X_DRAG_ACTIVE]),
                "lease_left_s": round(lease_left, 4),
                "holder": None if self.holder is None else self.holder.who(),
            },
            "profile": self._profile_status(x),
            "payload": dict(self.payload),
            "axes": self._axes(x),
            "overruns": int(x[ch.X_OVERRUNS]),
            "timing_us": {
                "wakeup_us": float(rec["wakeup_us"]),
                "compute_us": float(rec["compute_us"]),
                "wakeup_p99": float(self.chan.fctl[ch.WAKE_P99]),
                "compute_p99": float(self.chan.fctl[ch.COMP_P99]),
            },
        }

    # ------------------------------------------------------------------ end

    def finish(self) -> None:
        """The loop has ended: save a taught path still open, answer who waits, close."""
        if self._planner is not None:  # a plan nobody will play
            self._planner.proc.kill()
            self._planner.close()
            self._planner = None
        self._teach(time.monotonic())
        self._save_recording(time.monotonic(), at_end=True)
        for job in list(self.jobs) + ([self.inflight] if self.inflight else []):
            self._answer(job, {"ok": False, "message": "the service is stopping"})
        self.jobs.clear()
        self.inflight = None
        for c in list(self.conns.values()):
            self._flush(c)
            self._close(c)
        if self.listener is not None:
            try:
                self.sel.unregister(self.listener)
            except (KeyError, ValueError):
                pass
            self.listener.close()
        if self._rec_block is not None:
            self._rec_block.close()
            self._rec_block = None


_PRELOAD: threading.Thread | None = None


def preload_planner() -> None:
    """Import the taught path's fit (scipy.interpolate, ~2 s of CPU on a loaded machine) in a
    thread of the control-plane process, once, after it is up: every forked planner inherits
    it instead of importing it before its first chunk. :class:`Planner` joins the thread
    before it forks (a fork while another thread holds the import lock would deadlock the
    child)."""
    global _PRELOAD
    if _PRELOAD is None:
        from importlib import import_module

        _PRELOAD = threading.Thread(
            target=import_module, args=("scipy.interpolate",), name="hofto-preload", daemon=True
        )
        _PRELOAD.start()


class Planner:
    """Planning in a forked child process (ruckig and the taught path's fit hold the GIL:
    in a thread they would hold the socket up). The child sends a head (what the plan is,
    its length and first row), then the rows in chunks of PLAN_CHUNK as it samples them,
    then "end"; :meth:`step` reads one message."""

    def __init__(self, cmd, file, target, q_now, model, limits, dt) -> None:
        import multiprocessing as mp

        if _PRELOAD is not None:
            _PRELOAD.join()  # no fork while the preload's thread holds the import lock
        ctx = mp.get_context("fork")
        self.conn, child = ctx.Pipe(duplex=False)
        self.proc = ctx.Process(
            target=_plan_child,
            args=(child, self.conn, cmd, file, target, q_now, model, limits, dt),
            name="hofto-plan",
            daemon=True,
        )
        self.proc.start()
        child.close()
        self.error = ""
        self.head: dict[str, Any] | None = None
        #: the chunk read by the last step: (first row, q, qd, qdd), taken by the caller
        self.chunk: tuple[int, np.ndarray, np.ndarray, np.ndarray] | None = None
        self.ended = False
        self.play_queued = False  # the loop was asked to play it
        self.playing = False  # the loop took it

    def step(self) -> bool:
        """Read one message if there is one (True: one was read, or the planner is gone)."""
        if not self.conn.poll():
            if not self.proc.is_alive() and not self.conn.poll():
                self.error = self.error or "planning failed: the planner process died"
                return True
            return False
        try:
            kind, payload = self.conn.recv()
        except (EOFError, OSError):
            self.error = "planning failed: the planner process died"
            return True
        if kind == "error":
            self.error = payload
        elif kind == "head":
            self.head = payload
        elif kind == "rows":
            self.chunk = payload
        else:
            self.ended = True
        return True

    def close(self) -> None:
        self.conn.close()
        if not self.ended:
            self.proc.kill()  # nobody reads the rest of it
        self.proc.join(timeout=1.0)
        if self.proc.is_alive():
            self.proc.kill()
            self.proc.join()


def _plan_child(conn, parent_end, cmd, file, target, q_now, model, limits, dt) -> None:
    """The planner process: plan, send the head, the rows in chunks (sampled one chunk at a
    time: a send waits while the pipe is full, so only what the server takes is sampled),
    then "end". It dies with the control plane (PR_SET_PDEATHSIG) and on SIGTERM (not the
    server's handler), and holds no read end of its pipe (a write to a gone reader fails
    instead of blocking)."""
    import signal

    parent_end.close()
    import stat

    # the server's sockets (listener, clients): a client the server closes must see it now,
    # not when this plan is done
    for name in os.listdir("/proc/self/fd"):
        fd = int(name)
        if fd > 2 and fd != conn.fileno():
            try:
                if stat.S_ISSOCK(os.fstat(fd).st_mode):
                    os.close(fd)
            except OSError:
                pass
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    _die_with_parent()
    try:  # behind the control plane and its clients for CPU
        os.setpriority(os.PRIO_PROCESS, 0, PLANNER_NICE)
    except OSError:
        pass
    try:
        if cmd == "replay":
            plan, kind, mode, path = teach.stream_replay(Path(file), q_now, model, limits, dt)
        else:
            if cmd == "move_linear":
                pb = teach.plan_linear(target, q_now, model, limits, dt)
            else:
                pb = teach.plan_move(target, q_now, model, limits, dt)
            plan, kind, mode, path = pb.traj, pb.kind, pb.mode, pb.file
    except UserError as exc:
        conn.send(("error", str(exc)))
        conn.close()
        return
    except Exception as exc:  # a planner bug: one line, the service goes on
        conn.send(("error", f"planning failed: {type(exc).__name__}: {exc}"))
        conn.close()
        return
    rows = plan.n_rows
    head = {"kind": kind, "mode": mode, "file": path, "dt": plan.dt, "rows": rows,
            "segments": list(plan.segments), "scale": float(plan.scale),
            "q0": np.array(plan.rows(0, 1)[0][0])}  # fmt: skip
    try:
        conn.send(("head", head))
        for i in range(0, rows, PLAN_CHUNK):
            q, qd, qdd = plan.rows(i, min(rows, i + PLAN_CHUNK))
            conn.send(("rows", (i, q, qd, qdd)))
        conn.send(("end", None))
    except (BrokenPipeError, OSError):  # the server stopped reading: the plan is not played
        pass
    conn.close()


def _die_with_parent() -> None:
    """SIGKILL this process when its parent (the control plane) dies (Linux prctl)."""
    import ctypes
    import signal

    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(1, int(signal.SIGKILL), 0, 0, 0)  # PR_SET_PDEATHSIG = 1
    except (OSError, AttributeError):
        pass


def _alive(pid: int) -> bool:
    """Whether process ``pid`` runs (a zombie does not: the writer is the loop's child)."""
    if pid <= 0:
        return False
    try:
        with open(f"/proc/{pid}/stat", "rb") as f:
            return f.read().rsplit(b")", 1)[1].split()[0] != b"Z"
    except (OSError, IndexError):
        return False


def _acceleration(bits: int) -> dict[str, Any] | None:
    """The loop's X_ACCEL bits as hofto_hw.runtime.acceleration.report's dict (None: unknown)."""
    if bits < 0:
        return None
    out: dict[str, Any] = {
        "compiled": bool(bits & ch.ACCEL_COMPILED),
        "kernels": "numba" if bits & ch.ACCEL_NUMBA else "python",
        "native": bool(bits & ch.ACCEL_NATIVE),
    }
    if bits & ch.ACCEL_HAS_FUSED:
        out["fused"] = bool(bits & ch.ACCEL_FUSED)
    out["why"] = "" if out["compiled"] else "the tick did not take the compiled path (see its log)"
    return out
