"""Starting the control plane: the socket path's checks, the listening socket, the process.

:func:`check_socket_path` runs before ``hofto-hw run`` creates anything (flight log,
shared memory): a path too long for AF_UNIX (108 bytes with its NUL), in a folder that does
not exist or is not writable, under /proc or /sys, or taken by anything but a stale socket
is one line naming ``--socket``. :func:`listen` binds it (mode from ``service.socket_mode``,
never world-accessible between bind and chmod).

:class:`ControlPlaneProcess` hands the control plane's process (started by
:class:`~hofto_hw.runtime.prestart.Prestarted`, importing while the loop starts up, or by
itself) the listening socket's descriptor and the pickled arguments (as the flight recorder's
writer), at normal priority (SCHED_OTHER, the nice value the service started with; its
planner at nice 5), on the CPUs outside the loop's when the loop is pinned (``loop.cpus``,
hofto_hw.runtime.realtime.cpus_beside_loop; the writer's rule too): on a machine of two or
more CPUs the planner's CPU time is not taken on the loop's CPU. It also starts the stop
socket's process (:mod:`~hofto_hw.control_plane.stop_server`) with the stop socket's. Both
serve until the loop sets LOOP_DONE or their parent dies; a SIGTERM to the whole service only
starts a grace period for the control plane (the loop still stops the arm and says so) and is
ignored by the stop server, SIGINT is the loop's. :class:`InProcessControl` runs the same
server in a thread of the loop's process: for tests and tools that drive a sim-clock loop
themselves.
"""

from __future__ import annotations

import gc
import os
import signal
import socket
import stat
import subprocess
import threading
import time
from pathlib import Path
from typing import Any

from drivers.sim.control_socket import check_control_path, claim_control_path
from hofto_hw.control_plane.channel import LOOP_DONE, Channel
from hofto_hw.control_plane.port import LoopPort
from hofto_hw.errors import UserError
from hofto_hw.runtime.prestart import Prestarted
from hofto_hw.runtime.startup import CONTROL_MODULE

AF_UNIX_PATH_MAX = 107  # bytes of a socket path (sun_path is 108 with the NUL)
TERM_GRACE = 10.0


def check_socket_path(path: Path | str, option: str = "--socket") -> Path:
    """Refuse (UserError, one line) a control-socket path before anything is created."""
    raw = os.fsencode(path)
    if not raw or b"\0" in raw:
        raise UserError(f"{option}: {str(path)!r} is not a usable path")
    p = Path(os.path.abspath(path))
    if len(os.fsencode(p)) > AF_UNIX_PATH_MAX:
        raise UserError(
            f"{option}: {str(p)!r} is {len(os.fsencode(p))} bytes; a Unix socket path holds at "
            f"most {AF_UNIX_PATH_MAX} (use a shorter folder, e.g. /run/hofto-hw)"
        )
    real = os.path.realpath(p.parent)
    for pseudo in ("/proc", "/sys"):
        if real == pseudo or real.startswith(pseudo + "/"):
            raise UserError(f"{option}: {str(p)!r} is under {pseudo}, where no socket can live")
    folder = p.parent
    if folder.exists() and not folder.is_dir():
        raise UserError(f"{option}: {str(folder)!r} (the socket's folder) is not a folder")
    check_control_path(p, option)  # folder exists; a file, folder or live socket refused
    if not os.access(folder, os.W_OK | os.X_OK):
        raise UserError(f"{option}: folder {str(folder)!r} is not writable")
    return p


def listen(path: Path, mode: int = 0o660, option: str = "--socket") -> socket.socket:
    """Bind and listen at ``path`` (checked; a stale socket there is replaced)."""
    claim_control_path(path, option)
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM | socket.SOCK_CLOEXEC)
    old = os.umask(0o177)
    try:
        sock.bind(str(path))
    except OSError as exc:
        sock.close()
        raise UserError(
            f"{option}: cannot create the socket {str(path)!r}: {exc.strerror}"
        ) from None
    finally:
        os.umask(old)
    os.chmod(path, mode)
    sock.listen(16)
    return sock


def remove_socket(path: Path) -> None:
    """Unlink ``path`` if it is (still) a socket."""
    try:
        if stat.S_ISSOCK(path.lstat().st_mode):
            path.unlink()
    except FileNotFoundError:
        pass


class ControlPlaneProcess:
    """The control plane in its own process (see the module docstring)."""

    def __init__(
        self,
        cfg: Any,
        config_path: Path,
        listener: socket.socket | None,
        *,
        observers: list[str],
        log_path: str | None = None,
        recorder: dict[str, Any] | None = None,
        notify: bool = False,
        process: Prestarted | None = None,
        stop_listener: socket.socket | None = None,
    ) -> None:
        self.system: Any = None
        self.port: LoopPort | None = None
        self.chan = Channel(len(cfg.robot.joints), max(1, len(observers)), create=True)
        from hofto_hw.runtime.realtime import cpus_beside_loop

        fds = [] if listener is None else [listener.fileno()]
        args = (
            self.chan.name,
            self.chan.n,
            self.chan.k,
            cfg,
            str(config_path),
            list(observers),
            listener is not None,
            log_path,
            recorder,
            notify,
            cpus_beside_loop(),
        )
        try:
            self.proc = process if process is not None else Prestarted(CONTROL_MODULE, fds=True)
            self.proc.send(args, fds)
        except BaseException:
            self.chan.close()
            raise
        finally:
            if listener is not None:
                listener.close()  # the child serves it
        self.stop_proc = None  # the stop socket's own process (stop_server.py)
        if stop_listener is not None:
            from hofto_hw.control_plane.stop_server import start

            lc = cfg.loop
            self.stop_proc = start(self.chan, stop_listener, lc.realtime, lc.priority)

    def attach(self, system: Any, watch_log: bool = False) -> None:
        """The loop polls the channel after every tick from now on (``watch_log``: the
        control plane watches the flight recorder, started with ``recorder``)."""
        self.system = system
        self.port = LoopPort(self.chan, system).attach(watch_log)

    def wait_ready(self, timeout: float = 60.0) -> bool:
        """Whether the process is up (it writes its pid into the channel)."""
        from hofto_hw.control_plane.channel import CP_PID, STOP_PID

        end = time.monotonic() + timeout
        stop = self.stop_proc
        while time.monotonic() < end:
            if int(self.chan.ctl[CP_PID]) and (stop is None or int(self.chan.ctl[STOP_PID])):
                return True
            if self.proc.poll() is not None or (stop is not None and stop.poll() is not None):
                return False
            time.sleep(0.01)
        return False

    def close(self, timeout: float = 10.0) -> None:
        """After the loop: tell the process, wait for it (it saves an open taught path)."""
        from hofto_hw.control_plane.channel import EXIT

        if self.port is not None:
            self.port.finish()
        else:
            self.chan.ctl[EXIT] = 1
            self.chan.ctl[LOOP_DONE] = 1
        for proc in (self.proc, self.stop_proc):
            if proc is None:
                continue
            try:
                proc.wait(timeout=timeout)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
        if self.port is not None:
            self.port.detach()
        self.chan.close()


class InProcessControl:
    """The control plane served by a thread of this process (tests, sim-clock tools)."""

    def __init__(self, path: Path, system: Any, mode: int = 0o660) -> None:
        from hofto_hw.control_plane.server import ControlPlane

        self.path = check_socket_path(path)
        self.system = system
        tick = system.tick
        self.chan = Channel(tick.n, max(1, len(tick.observers)), create=True)
        self.port = LoopPort(self.chan, system).attach()
        self.listener = listen(self.path, mode)
        self.server = ControlPlane(
            self.listener,
            self.chan,
            system.cfg,
            system.model,
            observer_names=list(system.observer_names),
        )
        self._done = threading.Event()
        self._thread = threading.Thread(target=self._serve, name="hofto-control", daemon=True)

    def _serve(self) -> None:
        self.server.serve(done=self._done.is_set)

    def start(self) -> InProcessControl:
        self._thread.start()
        return self

    def close(self) -> None:
        self.port.finish()
        self._done.set()
        self._thread.join(timeout=10.0)
        self.port.detach()
        remove_socket(self.path)
        self.chan.close()


def _drop_realtime() -> None:
    """SCHED_OTHER (the loop's SCHED_FIFO is not inherited), at the nice value it was
    started with: not ahead of the flight recorder's writer (nice 5), whose records the
    safety checks watch, nor of its clients (a bench run with it at nice -5, flooded, on a
    machine at load 17, dropped 54,372 records and latched log_failure)."""
    try:
        os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
    except (AttributeError, OSError):
        pass


class _NotifyView:
    """What runtime.service.Supervisor reads, from the channel (heartbeat: the loop's ticks)."""

    def __init__(self, chan: Channel) -> None:
        from hofto_hw.control_plane.channel import EXIT, TICKS

        class _Loop:
            @property
            def alive_ns(self_inner) -> int:
                return int(chan.ctl[TICKS])

        class _Tick:
            @property
            def exit_requested(self_inner) -> bool:
                return bool(chan.ctl[EXIT])

        self.loop = _Loop()
        self.tick = _Tick()


def preload() -> None:
    """What the process imports before its arguments arrive (it starts while the loop's
    process imports): the server and the model's composition."""
    from importlib import import_module

    for name in (
        "hofto_hw.control_plane.server",
        "hofto_hw.runtime.compose",
        "hofto_hw.runtime.service",
    ):
        import_module(name)


def child_main(args: tuple, fds: list[int], term: list[float]) -> int:
    """The control-plane process (see the module docstring), once it has its arguments;
    ``fds``: the listening socket when it serves one. ``term[0]``: the monotonic time of a
    SIGTERM to it (0: none yet), kept by the handler prestart installed."""
    _drop_realtime()
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    (name, n, k, cfg, config_path, observers, serves, log_path, recorder, notify, cpus) = args
    if cpus:  # off the loop's CPU (the planner, forked from here, inherits it)
        try:
            os.sched_setaffinity(0, cpus)
        except OSError:  # CPUs outside our cpuset: keep the inherited affinity
            pass
    from hofto_hw.control_plane.channel import CP_PID
    from hofto_hw.control_plane.server import ControlPlane, preload_planner
    from hofto_hw.runtime.compose import build_model

    chan = Channel(n, k, name=name)
    model = build_model(cfg)
    listener = None
    if serves:
        (fd,) = fds
        listener = socket.socket(fileno=fd)
    server = ControlPlane(
        listener, chan, cfg, model, observer_names=observers, config_path=config_path,
        log_path=log_path, recorder=recorder,
    )  # fmt: skip
    # what is built by now (config, model, imports: most of the heap) lives until exit: out
    # of the collector's sight, so a full collection during a flood of requests walks only
    # the objects made since (tens of ms less on a stop's answer)
    gc.collect()
    gc.freeze()
    sup = None
    if notify:
        from hofto_hw.runtime.service import Supervisor

        sup = Supervisor(
            _NotifyView(chan),
            cfg.service.watchdog_fraction,
            cfg.service.status_interval,
            status=lambda _view: server.status(),
        )
        sup.start()
    chan.ctl[CP_PID] = os.getpid()
    preload_planner()  # after READY: not on the service's start-up path
    parent = os.getppid()

    def done() -> bool:
        if os.getppid() != parent:
            return True
        return term[0] > 0.0 and time.monotonic() - term[0] > TERM_GRACE

    try:
        server.serve(done=done)
    finally:
        if sup is not None:
            sup.stop()
        ended = bool(chan.ctl[LOOP_DONE])
        chan.close()
    return 0 if ended else 1
