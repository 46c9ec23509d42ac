"""The service side of ``hofto-hw run``: the local control socket and the systemd supervisor.

:class:`ControlServer` serves an AF_UNIX stream socket (mode 0660, no network listener) in a
daemon thread: one request line (words split as a shell does, so a quoted path may hold
spaces), one JSON reply line. Requests: ``status``, ``reset``, ``stop``,
``mode hold|move|drag``, ``mode drag --record FILE [--force]``, ``mode replay FILE``,
``mode move-to q1,...,qn`` [rad], ``enable on|off`` (the enabling input of hand guiding
when ``drag.enable_input.source`` is ``socket``). The thread only reads the tick's state and
sets its request flags (one writer each), so it cannot stall a tick; the slow work of teach
and play (checking the output file, loading and planning a trajectory, saving the taught path
when the drag ends) happens here (hofto_hw/runtime/teach.py). A reply with
``"input_error": true`` refuses bad input (the client exits 2). A path that exists and
is not a stale socket is refused: the server never unlinks anything else.

:class:`Supervisor` sends sd_notify READY once, STATUS every ``status_interval``, WATCHDOG at
the interval systemd asked for but only while the loop finished a tick since the last pet
(a hung loop stops the pets and systemd kills the service), and STOPPING at the end.
"""

from __future__ import annotations

import json
import os
import shlex
import socket
import stat
import sys
import threading
import time
from pathlib import Path
from typing import Any

from drivers.sim.control_socket import claim_control_path
from hofto_hw.control.joint_motion import DRAG, HOLD, MODE_NAMES, MOVE
from hofto_hw.errors import UserError
from hofto_hw.runtime import teach
from hofto_hw.runtime.notify import Notifier, NotifyError, Watchdog


def status_of(system: Any) -> dict[str, Any]:
    """The state a ``status`` request answers (slow path)."""
    tick, loop = system.tick, system.loop
    stop = tick.stop
    if tick.exit_requested:
        state = "stopping"
    elif stop.stopping():
        state = "stopped"
    elif tick.enabling:
        state = "enabling"
    else:
        state = "running"
    return {
        "state": state,
        "mode": MODE_NAMES.get(tick.motion.mode, "?"),
        "category": int(stop.category),
        "faults": stop.latched_names(),
        "persisting": stop.persisting(),
        "ticks": int(loop.ticks),
        "overruns": int(tick.overruns),
        "timing_us": {"compute": loop.compute.summary(), "wakeup": loop.wakeup.summary()},
        "log": getattr(system, "log_path", None),
        "recorder": _recorder_status(getattr(system, "sink", None)),
        "teach": None if tick.recording is None else tick.recording.status(),
        "playback": _playback_status(tick.playback),
        "acceleration": getattr(system, "acceleration", None),  # what the tick runs
    }


def _playback_status(pb: Any) -> dict[str, Any] | None:
    if pb is None:
        return None
    k, total = pb.player.k, pb.traj.q.shape[0]
    return {
        "kind": pb.kind,
        "file": None if pb.file is None else str(pb.file),
        "progress": round(min(1.0, (k + 1) / total), 4),
        "completed": bool(pb.completed),
        "duration_s": round(pb.traj.duration, 3),
    }


def _recorder_status(sink: Any) -> dict[str, Any] | None:
    """The flight recorder's counters (None when the run does not log to a file)."""
    health = getattr(sink, "health", None)
    if not callable(health):
        return None
    try:
        h = health()
    except RuntimeError:  # not started or already closed
        return None
    return {
        "writer_alive": h.writer_alive,
        "state": h.state,
        "records_written": h.records_written,
        "records_flushed": h.records_flushed,
        "dropped": h.dropped,
        "records_lost": h.records_lost,
        "write_errors": h.write_errors,
        "pending": h.pending,
    }


class ControlServer:
    """See the module docstring."""

    def __init__(self, path: Path, system: Any, mode: int = 0o660) -> None:
        self.path = Path(path)
        self.system = system
        claim_control_path(self.path, "--socket")  # refuses anything but a stale socket
        self.sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM | socket.SOCK_CLOEXEC)
        old = os.umask(0o177)  # never world-accessible, not even between bind and chmod
        try:
            self.sock.bind(str(self.path))
        finally:
            os.umask(old)
        os.chmod(self.path, mode)
        self.sock.listen(4)
        self.sock.settimeout(0.2)
        self._done = threading.Event()
        self._thread = threading.Thread(target=self._serve, name="hofto-control", daemon=True)

    def start(self) -> None:
        self._thread.start()

    def close(self) -> None:
        self._done.set()
        self._thread.join(timeout=2.0)
        self.sock.close()
        try:
            if stat.S_ISSOCK(self.path.lstat().st_mode):
                self.path.unlink()
        except FileNotFoundError:
            pass

    def poll(self) -> str:
        """Save a taught path whose drag has ended (every 0.2 s and after each request)."""
        msg = teach.save_finished(self.system.tick)
        if msg:
            print(f"hofto-hw run: {msg}", file=sys.stderr, flush=True)
        return msg

    def _serve(self) -> None:
        while not self._done.is_set():
            self.poll()
            try:
                conn, _ = self.sock.accept()
            except TimeoutError:
                continue
            except OSError:
                return
            with conn:
                conn.settimeout(2.0)
                try:
                    line = conn.makefile("r").readline().strip()
                    reply = self.handle(line)
                    conn.sendall((json.dumps(reply) + "\n").encode())
                except OSError:
                    continue

    def handle(self, line: str) -> dict[str, Any]:
        """Answer one request line."""
        tick = self.system.tick
        try:
            words = shlex.split(line)
        except ValueError as exc:
            return {"ok": False, "error": f"request {line!r}: {exc}"}
        if not words:
            return {"ok": False, "error": "empty request"}
        cmd = words[0]
        if cmd == "status":
            return {"ok": True, **status_of(self.system)}
        if cmd == "stop":
            tick.stop_requested = True
            return {"ok": True, "message": "stop requested"}
        if cmd == "reset":
            if not tick.exit_requested and tick.stop_requested:
                tick.stop_requested = False  # an operator stop ends with its reset
                seen = self.system.loop.ticks
                end = time.monotonic() + 2.0
                while self.system.loop.ticks < seen + 2 and time.monotonic() < end:
                    time.sleep(0.002)  # two ticks: the request is no longer a present cause
            tick.reset_result = ""
            tick.reset_requested = True
            deadline = time.monotonic() + 5.0
            while time.monotonic() < deadline:
                r = tick.reset_result
                if r and r != "resetting drive faults":
                    return {"ok": not r.startswith("reset refused"), "message": r}
                time.sleep(0.005)
            return {"ok": False, "message": "the loop did not answer the reset"}
        if cmd == "mode" and len(words) >= 2:
            reply = self._mode(words[1:])
            if reply is not None:
                return reply
        if cmd == "enable" and len(words) == 2 and words[1] in ("on", "off"):
            inp = tick.enable_input
            if inp.source != "socket":
                return {
                    "ok": False,
                    "message": f"drag.enable_input.source is {inp.source!r}, not 'socket'",
                }
            inp.set(words[1] == "on")  # one writer: this thread
            return {"ok": True, "message": f"enabling input {words[1]}"}
        return {
            "ok": False,
            "error": f"unknown request {line!r} (status, reset, stop, mode hold|move|drag, "
            "mode drag --record FILE [--force], mode replay FILE, mode move-to q1,...,qn, "
            "enable on|off)",
        }

    def _mode(self, args: list[str]) -> dict[str, Any] | None:
        """``mode ...`` requests; None for an unknown form."""
        tick = self.system.tick
        what, rest = args[0], args[1:]
        known = (what in ("hold", "move") and not rest) or what == "drag"
        known = known or (what in ("replay", "move-to") and len(rest) == 1)
        if not known:
            return None
        if tick.stop.stopping():
            return {"ok": False, "message": "a stop is latched: reset first"}
        try:
            if what == "drag":
                return self._enter_drag(self._recording(rest))
            if what in ("replay", "move-to"):
                return self._play(what, rest[0])
        except UserError as exc:
            return {"ok": False, "input_error": True, "message": str(exc)}
        if what == "move" and tick.motion.path is None:  # else accepted and nothing moves
            return {"ok": False, "message": "mode move: the config has no demo path (run.path)"}
        tick.mode_request = MOVE if what == "move" else HOLD
        msg = f"mode {what} requested"
        if what == "hold" and tick.recording is not None and tick.recording.state < teach.SAVED:
            saved = self._wait_saved()
            msg += f"; {saved}" if saved else ""
        return {"ok": True, "message": msg}

    def _recording(self, rest: list[str]) -> teach.Recording | None:
        """``--record FILE [--force]`` -> a Recording (output file checked), or None."""
        if not rest:
            return None
        force = "--force" in rest
        words = [w for w in rest if w != "--force"]
        if len(words) != 2 or words[0] != "--record":
            raise UserError(f"mode drag: expected --record FILE [--force], got {' '.join(rest)}")
        file = teach.check_output(words[1], force)
        system = self.system
        capacity = round(system.cfg.motion.record_seconds * system.rate_hz)
        return teach.Recording(file, force, system.model, capacity)

    def _wait_saved(self) -> str:
        """After ``mode hold``: wait (a few ticks) for the drag to end, save the taught path."""
        tick = self.system.tick
        rec = tick.recording
        deadline = time.monotonic() + 2.0
        while rec.state < teach.FINISHED and time.monotonic() < deadline:
            time.sleep(0.002)
        return self.poll() or rec.message

    def _wait_mode(self) -> str:
        """Wait (a few ticks) for the tick's answer to a mode request."""
        tick = self.system.tick
        deadline = time.monotonic() + 2.0
        while time.monotonic() < deadline:
            r = tick.mode_result
            if r:
                return r
            time.sleep(0.002)
        return "the loop did not answer the mode request"

    def _enter_drag(self, rec: teach.Recording | None = None) -> dict[str, Any]:
        """Request drag mode (recording the taught path into ``rec``) and wait for the tick."""
        tick = self.system.tick
        if tick.drag is None:
            return {"ok": False, "message": "no drag: section in the config"}
        self.poll()  # a finished earlier recording is saved before the tick lets it go
        tick.mode_result = ""
        tick.record_request = rec
        tick.mode_request = DRAG
        r = self._wait_mode()
        if r != "drag":
            return {"ok": False, "message": r}
        where = f", recording the taught path to {rec.file}" if rec is not None else ""
        return {"ok": True, "message": f"mode drag{where}"}

    def _play(self, what: str, arg: str) -> dict[str, Any]:
        """Plan (here, off the tick) a taught-path replay or a move to a joint target from the
        held position and hand it to the tick."""
        system = self.system
        tick, model = system.tick, system.model
        if tick.motion.mode != HOLD:
            name = MODE_NAMES.get(tick.motion.mode, "?")
            return {"ok": False, "message": f"refused: the arm is in mode {name}: mode hold first"}
        q_now = tick.motion.q.copy()
        limits = teach.motion_limits(system.cfg, model)
        dt = 1.0 / system.rate_hz
        if what == "replay":
            pb = teach.plan_replay(Path(arg), q_now, model, limits, dt)
        else:
            pb = teach.plan_move(teach.parse_joints(arg), q_now, model, limits, dt)
        tick.mode_result = ""
        tick.play_request = pb
        tick.mode_request = pb.mode
        r = self._wait_mode()
        if r != "playing":
            return {"ok": False, "message": r}
        tr = pb.traj
        if pb.kind == "replay":
            to_start = tr.segments[1] * tr.dt
            text = (
                f"replaying {arg}: {to_start:.2f} s to its start, then {tr.duration - to_start:.2f}"
                f" s along it (time scale {tr.scale:.2f})"
            )
        else:
            text = f"moving to the joint target in {tr.duration:.2f} s"
        return {"ok": True, "message": text}


class Supervisor:
    """sd_notify READY/STATUS/WATCHDOG/STOPPING for ``loop`` (see the module docstring).

    Sending is :class:`~hofto_hw.runtime.notify.Notifier`'s, petting is
    :class:`~hofto_hw.runtime.notify.Watchdog`'s with the loop's ``alive_ns`` as heartbeat;
    a failed send is counted (``errors``, ``last_error``), never raised into the service.
    """

    def __init__(
        self,
        system: Any,
        fraction: float = 0.5,
        status_interval: float = 1.0,
        status: Any = status_of,
    ):
        self.system = system
        self.status = status
        self.notifier = Notifier()
        self.watchdog = Watchdog(self.notifier, lambda: system.loop.alive_ns, fraction)
        self.interval = self.watchdog.interval
        self.status_interval = status_interval
        self.errors = 0
        self.last_error = ""
        self._done = threading.Event()
        self._thread = threading.Thread(target=self._run, name="hofto-notify", daemon=True)

    def start(self) -> None:
        self._thread.start()

    def stop(self) -> None:
        self._done.set()
        self._thread.join(timeout=2.0)
        self.watchdog.stop()
        self._send("STOPPING=1")

    def _send(self, message: str) -> None:
        try:
            self.notifier.send(message)
        except NotifyError as exc:
            self.errors += 1
            self.last_error = str(exc)

    def _run(self) -> None:
        loop = self.system.loop
        while loop.alive_ns == 0 and not self._done.wait(0.01):
            pass  # READY only once the loop has run a tick
        self._send("READY=1")
        self.watchdog.start()  # pets only while the loop finished a tick since the last pet
        next_status = 0.0
        stopping_sent = False
        step = min(self.interval or self.status_interval, self.status_interval)
        while not self._done.wait(step):
            if self.system.tick.exit_requested and not stopping_sent:
                self._send("STOPPING=1")
                stopping_sent = True
            now = time.monotonic()
            tick = getattr(self.system, "tick", None)
            if tick is not None and hasattr(loop, "wakeup"):
                tick.wakeup_p99_us = loop.wakeup.percentile(99.0)  # for the diag records
                tick.compute_p99_us = loop.compute.percentile(99.0)
            if now >= next_status:
                s = self.status(self.system)
                self._send(
                    f"STATUS={s['state']}, {s['ticks']} ticks, faults: "
                    f"{', '.join(s['faults']) or 'none'}"
                )
                next_status = now + self.status_interval
