"""The Python program interface of a running ``hofto-hw run`` (docs/client.md).

    from hofto_hw.client import Robot

    with Robot.connect(socket="/run/hofto-hw/control.sock") as robot:
        s = robot.state()                       # q [rad], tau_ext per observer [N·m], ...
        robot.move_joints(s.q + 0.1, speed=0.5).wait(timeout=30)
        for rec in robot.stream(rate_hz=100):   # the loop's ticks, read-only
            ...

Every refusal or failure is an exception carrying the service's one-line reason
(:class:`Refused`, :class:`ServiceError`).
"""

from __future__ import annotations

import contextlib
import threading
import time
import warnings
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from hofto_hw.client.connection import Connection, Refused, ServiceError, send_stop
from hofto_hw.client.stream import RingReader, TickRecord
from hofto_hw.runtime.control_client import DEFAULT_SOCKET


@dataclass
class Enabling:
    """The enabling input: ``source`` (socket / digital_input / scripted), ``pressed``,
    ``drag_active``, ``lease_left_s`` [s] of the remote lease, ``holder`` (who holds
    motion and enabling, or None)."""

    source: str
    pressed: bool
    drag_active: bool
    lease_left_s: float
    holder: str | None


@dataclass
class ActivePayload:
    """The load the service's model carries: ``mass`` [kg] at ``com`` (3,) [m] in the tool
    frame (``safety.payload`` until a client sets another, :meth:`Robot.set_payload`)."""

    mass: float
    com: np.ndarray


@dataclass
class Axis:
    """One drive's commissioning state: ``name`` (the joint), ``sto`` (safe torque off
    active: the power stage cannot be on; None where its drive profile's source is not in
    the process image: an object read by SDO, or the drive state), ``brake`` ("closed",
    "open", or None where the stack does not see the brake: a real bus)."""

    name: str
    sto: bool | None
    brake: str | None


@dataclass
class State:
    """A snapshot of the arm (SI): loop time ``t`` [s] and ``tick``; ``mode``; latched
    ``faults`` and stop ``category`` (-1: none); ``q``, ``qd``, ``q_cmd`` (n,) [rad,
    rad/s]; ``tau`` (n,) [N·m] motor torque; ``tau_ext`` {observer: (n,)} [N·m] estimated
    external torques; ``wrench`` (6,) [N, N·m] tool wrench (NaN outside drag);
    ``tcp_position`` (3,) [m] and ``tcp_rotation`` (3, 3) of the tool frame in the base
    frame; ``enabling``; ``profile`` (active safety profile, None: the config's);
    ``overruns``; ``timing_us``; ``axes`` (n,) :class:`Axis` (safe torque off and holding
    brake per drive); ``payload`` (:class:`ActivePayload`)."""

    t: float
    tick: int
    mode: str
    faults: list[str]
    category: int
    moving: bool
    q: np.ndarray
    qd: np.ndarray
    q_cmd: np.ndarray
    tau: np.ndarray
    tau_ext: dict[str, np.ndarray]
    wrench: np.ndarray
    tcp_position: np.ndarray
    tcp_rotation: np.ndarray
    enabling: Enabling
    profile: str | None
    overruns: int
    timing_us: dict[str, float]
    axes: list[Axis]
    payload: ActivePayload | None = None


def _payload_of(p: Any) -> ActivePayload | None:
    if p is None:
        return None
    return ActivePayload(float(p["mass"]), _arr(p["com"], "payload.com", (3,)))


def _arr(v: Any, what: str, shape: tuple[int, ...] | None = None) -> np.ndarray:
    try:
        a = (
            np.array([np.nan if x is None else x for x in v], dtype=float)
            if (v and not isinstance(v[0], list))
            else np.array([[np.nan if x is None else x for x in row] for row in v], dtype=float)
        )
    except (TypeError, ValueError):
        raise ServiceError(f"malformed answer: state.{what} is not an array of numbers") from None
    if shape is not None and a.shape != shape:
        raise ServiceError(f"malformed answer: state.{what} has shape {a.shape}, not {shape}")
    return a


def _axes_of(v: Any, n: int) -> list[Axis]:
    if not isinstance(v, list) or len(v) != n:
        raise ServiceError(f"malformed answer: state.axes is not a list of {n} axes")
    out = []
    for a in v:
        brake = a["brake"]
        if brake not in (None, "open", "closed") or a["sto"] not in (None, True, False):
            raise ServiceError(f"malformed answer: state.axes: {str(a)[:60]}")
        out.append(Axis(str(a["name"]), a["sto"], brake))
    return out


def _state_of(r: dict[str, Any], n: int) -> State:
    try:
        en = r["enabling"]
        return State(
            t=float(r["t"]),
            tick=int(r["tick"]),
            mode=str(r["mode"]),
            faults=[str(f) for f in r["faults"]],
            category=int(r["category"]),
            moving=bool(r["moving"]),
            q=_arr(r["q"], "q", (n,)),
            qd=_arr(r["qd"], "qd", (n,)),
            q_cmd=_arr(r["q_cmd"], "q_cmd", (n,)),
            tau=_arr(r["tau"], "tau", (n,)),
            tau_ext={str(k): _arr(v, f"tau_ext.{k}", (n,)) for k, v in r["tau_ext"].items()},
            wrench=_arr(r["wrench"], "wrench", (6,)),
            tcp_position=_arr(r["tcp_position"], "tcp_position", (3,)),
            tcp_rotation=_arr(r["tcp_rotation"], "tcp_rotation", (3, 3)),
            enabling=Enabling(
                str(en["source"]),
                bool(en["pressed"]),
                bool(en["drag_active"]),
                float(en["lease_left_s"]),
                None if en["holder"] is None else str(en["holder"]),
            ),
            profile=None if r.get("profile") is None else str(r["profile"]["name"]),
            overruns=int(r["overruns"]),
            timing_us={str(k): float(v) for k, v in r["timing_us"].items()},
            axes=_axes_of(r["axes"], n),
            payload=_payload_of(r.get("payload")),
        )
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise ServiceError(f"malformed answer: state: {type(exc).__name__}: {exc}") from None


class Motion:
    """A move or replay the service accepted: :meth:`wait`, :meth:`cancel`, ``done``,
    ``result`` ("completed", "cancelled", "stopped: FAULTS" once done, else None)."""

    def __init__(self, robot: Robot, kind: str, message: str, duration_s: float) -> None:
        self.robot = robot
        self.kind = kind
        self.message = message
        self.duration_s = duration_s
        self.result: str | None = None
        self._cancelled = False

    @property
    def done(self) -> bool:
        if self.result is None:
            self._poll()
        return self.result is not None

    def _poll(self) -> None:
        s = self.robot.status()
        pb = s.get("playback") or {}
        if s.get("faults"):
            self.result = "stopped: " + ", ".join(s["faults"])
        elif s.get("mode") == "hold" and pb.get("completed"):
            self.result = "completed"
        elif s.get("mode") == "hold" and self._cancelled:
            self.result = "cancelled"

    def wait(self, timeout: float | None = None) -> str:
        """Until done (polls the status); TimeoutError after ``timeout`` [s]. The result."""
        end = None if timeout is None else time.monotonic() + timeout
        while not self.done:
            if end is not None and time.monotonic() > end:
                raise TimeoutError(f"{self.kind}: not done within {timeout:g} s")
            time.sleep(0.02)
        return self.result  # type: ignore[return-value]

    def cancel(self) -> None:
        """Decelerate to standstill within the limits and hold (not a stop: nothing latches)."""
        self._cancelled = True
        self.robot._call({"cmd": "cancel"})


class Robot:
    """A client of the control socket (see the module docstring). One connection; the
    methods may be called from several threads (one request at a time)."""

    def __init__(self, conn: Connection, socket: Path, timeout: float) -> None:
        self.conn = conn
        self.socket = socket
        self.timeout = timeout
        self._lock = threading.Lock()
        self.info = self._call({"cmd": "hello", "name": "hofto_hw.client"})
        end = time.monotonic() + timeout  # a service just started: its loop's first tick
        while self._call({"cmd": "status"})["state"] == "starting":
            if time.monotonic() > end:
                raise ServiceError(f"{socket}: the loop has not started within {timeout:g} s")
            time.sleep(0.01)
        self.n = len(self.info["joints"])
        self.lease_s = float(self.info["lease_s"])
        self._watchers: list[threading.Thread] = []
        self._closed = threading.Event()
        #: "" when the last stop() went through the stop socket, else why it did not
        self.stop_note = ""

    @classmethod
    def connect(cls, socket: Path | str = DEFAULT_SOCKET, timeout: float = 10.0) -> Robot:
        """Connect to the service at ``socket``; ServiceError (one line) when it is not
        there or does not answer."""
        path = Path(socket)
        return cls(Connection(path, timeout), path, timeout)

    def __enter__(self) -> Robot:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        self._closed.set()
        for t in self._watchers:
            t.join(timeout=2.0)
        self.conn.close()

    # ------------------------------------------------------------------ requests

    def _call(self, req: dict[str, Any], timeout: float | None = None) -> dict[str, Any]:
        with self._lock:
            r = self.conn.call(req, timeout)
        if not r["ok"]:
            raise Refused(str(r.get("message") or r.get("error") or "refused"), r)
        return r

    def status(self) -> dict[str, Any]:
        """The service's status (state machine, faults, timing, log, teach, playback)."""
        return self._call({"cmd": "status"})

    def state(self) -> State:
        """A typed snapshot of the arm (:class:`State`)."""
        return _state_of(self._call({"cmd": "state"}), self.n)

    def stop(self) -> str:
        """Stop the arm (the configured category of stop_request) through the stop socket
        beside the control socket (``<socket>.stop``: a process that serves stops only,
        answering once the loop has acknowledged it), on a connection of its own. Without
        a stop socket (an older service) through the control socket's ``stop``, answered
        first there, with a RuntimeWarning saying so (``stop_note`` keeps the line)."""
        r, self.stop_note = send_stop(self.socket, self.timeout)
        if self.stop_note:
            warnings.warn(self.stop_note, RuntimeWarning, stacklevel=2)
        if not r["ok"]:
            raise Refused(str(r.get("message")), r)
        return str(r.get("message", ""))

    def release(self) -> None:
        """Give up motion and the enabling input (held since this client's first motion
        request, :meth:`set_payload` or :meth:`set_safety_profile`), so that another
        client may take them; closing the connection does the same."""
        self._call({"cmd": "release"})

    def reset(self) -> str:
        """Reset the latched faults (Refused naming the cause that persists)."""
        return str(self._call({"cmd": "reset"}).get("message", ""))

    def move_joints(
        self,
        q: Any,
        speed: float = 1.0,
        acceleration: float = 1.0,
        wait: bool = True,
        timeout: float | None = None,
    ) -> Motion:
        """A jerk-limited move to joint target ``q`` (n,) [rad] at fractions ``speed`` and
        ``acceleration`` of the ``motion:`` limits; refused (one line) when out of limits.
        ``wait``: return once done."""
        qv = [float(v) for v in np.asarray(q, dtype=float).ravel()]
        if not all(np.isfinite(qv)):
            raise Refused("move_joints: q has a non-finite value")
        req = {"cmd": "move_joints", "q": qv, "speed": float(speed),
               "acceleration": float(acceleration)}  # fmt: skip
        return self._motion(req, "move", 60.0, wait, timeout)

    def move_linear(
        self,
        pose: Any,
        speed: float = 1.0,
        acceleration: float = 1.0,
        wait: bool = True,
        timeout: float | None = None,
    ) -> Motion:
        """The tool frame along a straight line to ``pose`` = [x, y, z, rx, ry, rz] (base
        frame, [m] and rotation vector [rad]), jerk-limited within the ``motion:`` limits
        (fractions ``speed``, ``acceleration``); refused before moving when the line leaves
        the reach, crosses a singularity or needs a joint outside its limits."""
        p = [float(v) for v in np.asarray(pose, dtype=float).ravel()]
        if len(p) != 6 or not all(np.isfinite(p)):
            raise Refused("move_linear: pose must be 6 finite numbers [x, y, z, rx, ry, rz]")
        req = {"cmd": "move_linear", "pose": p, "speed": float(speed),
               "acceleration": float(acceleration)}  # fmt: skip
        return self._motion(req, "linear", 120.0, wait, timeout)

    def replay(
        self, path_file: Path | str, wait: bool = True, timeout: float | None = None
    ) -> Motion:
        """Replay a taught path (``hofto-hw mode drag --record``'s file): a move to its
        start, then the path time-scaled into the limits."""
        path = str(Path(path_file).resolve())
        # the answer waits for the planning, which is CPU-bound: a long call timeout
        return self._motion({"cmd": "replay", "file": path}, "replay", 600.0, wait, timeout)

    def _motion(
        self,
        req: dict[str, Any],
        kind: str,
        call_timeout: float,
        wait: bool,
        timeout: float | None,
    ) -> Motion:
        """Send a motion request (answered once planned, within ``call_timeout`` [s]); its
        :class:`Motion`, waited for up to ``timeout`` [s] when ``wait``."""
        r = self._call(req, timeout=call_timeout)
        m = Motion(self, kind, str(r.get("message", "")), float(r.get("duration_s", 0.0)))
        if wait:
            m.wait(timeout)
        return m

    @contextlib.contextmanager
    def drag(self, record: Path | str | None = None, force: bool = False) -> Iterator[Robot]:
        """Hand guiding while the block runs: drag mode (recording the taught path into the
        new file ``record``), the enabling input held as a lease renewed every third of
        ``drag.enable_input.lease`` by a thread of this client. On leaving: hold (the
        drag ramps down, the taught path is saved: ``last_drag_message``), then the lease
        is given up. If this process dies, the lease lapses and the arm stops (category 2,
        as a released enabling device)."""
        req: dict[str, Any] = {"cmd": "mode", "mode": "drag"}
        if record is not None:
            req["record"] = str(Path(record).resolve())
            if force:
                req["force"] = True
        self._call(req)
        stop = threading.Event()
        err: list[BaseException] = []

        def renew() -> None:
            while not stop.is_set():
                try:
                    self._call({"cmd": "enable", "on": True}, timeout=self.lease_s)
                except Exception as exc:  # the lease lapses by itself: the arm stops
                    err.append(exc)
                    return
                stop.wait(self.lease_s / 3.0)

        self._call({"cmd": "enable", "on": True})
        t = threading.Thread(target=renew, name="hofto-lease", daemon=True)
        t.start()
        try:
            yield self
        finally:
            # hold first (the drag ramps down, a taught path is saved), then let go
            try:
                r = self._call({"cmd": "mode", "mode": "hold"})
                self.last_drag_message = str(r.get("message", ""))
            finally:
                stop.set()
                t.join()
                self._call({"cmd": "enable", "on": False})
        if err:
            raise ServiceError(f"drag: the enabling lease was not renewed: {err[0]}")

    def home(self, joints: Any = None, timeout: float | None = None) -> str:
        """CiA 402 homing of ``joints`` (names or 1-based numbers; None: every joint with
        ``homing:`` in the config) by the loop, one after the other, each back to the loop's
        mode; returns the service's line (``homed: ...``). Refused (one line) while a fault
        is latched, the arm moves or another client holds motion; a homing that fails (time
        out, homing error, end position off the offset) is Refused naming the joint.
        ``timeout`` [s]: how long to wait for the answer (default: 300 s)."""
        req: dict[str, Any] = {"cmd": "home"}
        if joints is not None:
            items = [joints] if isinstance(joints, (str, int)) else list(joints)
            req["joints"] = [j if isinstance(j, int) else str(j) for j in items]
        return str(self._call(req, 300.0 if timeout is None else timeout)["message"])

    def zero_set(self, joint: str | int, at: float) -> str:
        """Re-zero ``joint`` (name or 1-based number), which a person has put at a reference
        angle ``at`` [rad]: the service rewrites its config's ``zero_offset`` (a backup
        kept, the change logged) and the loop reads the joint with it from the next tick.
        Refused while the arm moves or a fault is latched. Returns the logged line."""
        j = joint if isinstance(joint, int) else str(joint)
        return str(self._call({"cmd": "zero_set", "joint": j, "at": float(at)})["message"])

    def set_payload(self, mass: float, com: Any) -> ActivePayload:
        """The load on the tool from now on: ``mass`` [kg] at ``com`` (3,) [m] in the tool
        frame (as ur_rtde's setPayload). The service checks it against
        ``robot.rated_payload`` (0 <= mass <= the rated mass, com within its ``com_max``,
        its holding torque within ``holding_fraction`` of every joint's torque limit here
        and at the worst pose the joint limits allow) and the loop takes it at standstill
        only (Refused while the arm moves or the enabling input is pressed), ramped in over
        ``ramp_s`` (intermediate payloads: the feed-forward does not step); this returns
        when the whole payload is active, and its observers' and feed-forward's model carry
        it. A new call from another thread or client during the ramp supersedes it (this
        one is then Refused). Returns the active payload."""
        c = np.asarray(com, dtype=float).ravel()
        if c.shape != (3,) or not np.all(np.isfinite(c)) or not np.isfinite(float(mass)):
            raise Refused("set_payload: mass must be a finite number and com 3 finite numbers")
        r = self._call({"cmd": "set_payload", "mass": float(mass), "com": c.tolist()})
        p = _payload_of(r.get("payload"))
        if p is None:
            raise ServiceError("malformed answer: set_payload: no payload in the reply")
        return p

    def set_safety_profile(self, name: str) -> dict[str, Any]:
        """Make the config's ``safety.profiles.sets[name]`` active (collision thresholds
        scaled, motion speed limited, the drag's virtual mass, damping and speed limits
        scaled); only at standstill, else Refused. Returns its content."""
        return dict(self._call({"cmd": "set_safety_profile", "name": str(name)})["profile"])

    # ------------------------------------------------------------------ events, stream

    def on(self, event: str, callback: Callable[[dict[str, Any]], None]) -> None:
        """Call ``callback(event)`` for each new safety event named ``event`` ("collision",
        "stop_request", "enabling_released", "reset", "standstill", ...; "*": all), from
        a thread of this client (polls the service every 20 ms on its own connection)."""
        first = self._call({"cmd": "events"})["next"]

        def watch() -> None:
            since = first
            try:
                with Connection(self.socket, self.timeout) as c:
                    while not self._closed.wait(0.02):
                        r = c.call({"cmd": "events", "since": since})
                        for e in r.get("events", []):
                            since = max(since, int(e["seq"]) + 1)
                            if event in ("*", e.get("kind")):
                                callback(e)
            except ServiceError:
                return

        t = threading.Thread(target=watch, name=f"hofto-on-{event}", daemon=True)
        t.start()
        self._watchers.append(t)

    def stream(self, rate_hz: float = 100.0, count: int | None = None) -> Iterator[TickRecord]:
        """The loop's ticks at ``rate_hz`` (every k-th tick, k = loop rate / rate_hz), read
        from the flight recorder's shared-memory ring without touching it (needs a run with
        its flight log). A reader that fell a ring behind says so in ``skipped``."""
        info = self._call({"cmd": "stream_info"})
        if not info.get("shm"):
            raise Refused(str(info.get("message", "no flight recorder")))
        every = max(1, round(float(self.info["rate_hz"]) / float(rate_hz)))
        reader = RingReader(info["shm"], int(info["caps"][0]), self.n, list(self.info["observers"]))
        period = every / float(self.info["rate_hz"])
        got = 0
        pending = 0
        try:
            while count is None or got < count:
                for rec, skipped in reader.read():
                    pending += skipped
                    if int(rec["tick"]) % every:
                        continue
                    yield reader.record(rec, pending // every)
                    pending = 0
                    got += 1
                    if count is not None and got >= count:
                        return
                time.sleep(period / 2.0)
        finally:
            reader.close()
