"""``hofto-hw run``: the controller process (the fixed-rate loop on the drives).

The default config (``er3a``, configs/er3a.yaml) is the README's main job on the simulated arm:
the arm moves along the demo path, a scripted collision hits a link, the monitor stops the
arm, a scripted drag and replay follow and a short summary is printed (or written with
``--summary-json``). A deployment config (configs/er3a_service.yaml) scripts nothing and runs
until stopped (``run.duration: null``). SIGTERM or SIGINT: category 1 stop -> drives
disabled -> log closed -> exit 0.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import signal
import sys
import time
from pathlib import Path
from typing import Any

from hofto_hw.commands.args import output_file

DEFAULT_CONFIG = "er3a"  # the README's main job: the simulated arm's scripted scenario


def configure(parser: argparse.ArgumentParser) -> None:
    from hofto_hw.commands.args import add_config

    add_config(parser, default=DEFAULT_CONFIG)
    parser.add_argument(
        "--duration",
        type=float,
        default=None,
        help="run time [s] (default: the config's run.duration; er3a: 12 s; null in the "
        "config: until SIGTERM or Ctrl-C)",
    )
    parser.add_argument(
        "--clock",
        choices=("sim", "real"),
        default=None,
        help="real: the loop's period in wall time; sim: ticks back to back in simulated "
        "time (sim bus only) (default: the config's run.clock, real unless set)",
    )
    parser.add_argument("--summary-json", type=Path, default=None, help="write the summary")
    parser.add_argument(
        "--log-dir", type=Path, default=None, help="folder for the MCAP flight log (run.log_dir)"
    )
    parser.add_argument("--no-log", action="store_true", help="record no flight log")
    parser.add_argument(
        "--plot", type=output_file, metavar="PNG", help="draw the run from its log into PNG"
    )
    parser.add_argument("--no-collision", action="store_true", help="no scripted collision")
    parser.add_argument(
        "--socket", type=Path, default=None, help="serve the control socket at this path"
    )
    parser.add_argument("--hold", action="store_true", help="start in hold, not move")
    parser.add_argument(
        "--interface", default=None, help="bus.interface override (NIC for ethercat, CAN channel)"
    )


def remove_socket(path: Path) -> None:
    """The control plane's socket file and the stop socket beside it removed
    (hofto_hw.control_plane.process imported here: it imports the whole tick, seconds on a
    loaded machine, which belong to the start-up's "importing" phase, where SIGTERM is
    already a clean stop)."""
    from hofto_hw.control_plane.process import remove_socket as remove
    from hofto_hw.control_plane.protocol import stop_path

    remove(path)
    remove(stop_path(path))


def _check_duration(value: float | None) -> None:
    from hofto_hw.config.runtime import MAX_RUN_SECONDS
    from hofto_hw.errors import UserError

    if value is not None and (not math.isfinite(value) or value <= 0.0):
        raise UserError(f"--duration: must be a finite number of seconds > 0, got {value}")
    if value is not None and value > MAX_RUN_SECONDS:
        raise UserError(f"--duration: at most {MAX_RUN_SECONDS:g} s (a week), got {value:g}")


def _check_ticks(duration: float | None, rate_hz: float, given: bool) -> None:
    """A run shorter than one tick does nothing and would still say it ran (None: no end)."""
    from hofto_hw.errors import UserError

    if duration is not None and round(duration * rate_hz) < 1:
        where = "--duration" if given else "run.duration"
        raise UserError(
            f"{where}: {duration:g} s is less than one tick at loop.rate_hz = {rate_hz:g} Hz "
            f"(at least {0.5 / rate_hz:g} s)"
        )


def _observer_choice(cfg: object) -> str:
    """Which observers the loop runs and where their gains come from (loop.observers, or the
    top-level observers section when loop.observers leaves one out): said, never silent."""
    from hofto_hw.runtime.compose import loop_observer_names

    own = cfg.loop.observers or {}  # type: ignore[attr-defined]
    parts = [
        f"{name} ({'loop.observers' if name in own else 'observers: the offline gains'})"
        for name in loop_observer_names(cfg)  # type: ignore[arg-type]
    ]
    return "loop observers " + ", ".join(parts)


def _check_interface(cfg: object, interface: str | None) -> None:
    """--interface names the NIC or CAN channel of a real bus: refused where it cannot apply."""
    from hofto_hw.errors import UserError

    if interface is None:
        return
    bus = cfg.bus  # type: ignore[attr-defined]
    if bus is None or bus.transport == "sim":
        what = "no bus: section" if bus is None else "bus.transport sim (the simulated bus)"
        raise UserError(f"--interface {interface}: does not apply to {what}; it has no interface")


def run(args: argparse.Namespace) -> int:
    from hofto_hw.runtime.startup import Helpers, StartupInterrupted, StartupSignals

    signals = StartupSignals()  # SIGTERM/SIGINT before the loop: a clean stop, not a kill
    helpers = Helpers()  # the writer and control plane, started in _run
    try:
        return _run(args, signals, helpers)
    except StartupInterrupted as exc:
        quiet_interrupted_compile()
        print(
            f"hofto-hw run: {exc.name} during start-up: stopped (no drive left enabled, "
            "nothing left running)",
            file=sys.stderr,
        )
        return 0 if exc.signum == signal.SIGTERM else 128 + exc.signum
    finally:
        helpers.abandon()
        signals.restore()


def quiet_interrupted_compile() -> None:
    """After a start-up stop: a signal that came while numba compiled may have left llvmlite
    objects half built, and their ``__del__`` fails when the interpreter collects them at exit
    (``AttributeError: ... '_as_parameter_'``, printed as a traceback after the clean stop's
    line). They own nothing yet, so those messages are dropped; any other is printed."""
    default = sys.unraisablehook

    def hook(u: Any) -> None:
        if (getattr(u.object, "__module__", "") or "").startswith("llvmlite."):
            return
        default(u)

    sys.unraisablehook = hook


def _run(args: argparse.Namespace, signals: Any, helpers: Any) -> int:
    # Every module the start-up uses first (the control plane imports the tick: seconds on a
    # loaded machine), before the progress clock starts: a quick refusal (a bad option or
    # config, an SDO abort) stays one line. SIGTERM during them is already a clean stop
    # (run()). Then the helper processes, forked with these imports (none of their own to
    # do), before the progress thread and the real-time set-up (runtime.prestart).
    import hofto_hw.control_plane.process  # noqa: F401
    from hofto_hw.config import load_config
    from hofto_hw.config.locate import find_config
    from hofto_hw.control.joint_motion import MOVE
    from hofto_hw.errors import ConfigError
    from hofto_hw.outputs import check_output, write_atomic
    from hofto_hw.runtime import acceleration, realtime
    from hofto_hw.runtime.compose import build
    from hofto_hw.runtime.drag_script import run_loop
    from hofto_hw.runtime.positions import state_path
    from hofto_hw.runtime.startup import StartupProgress
    from hofto_hw.runtime.summary import build_summary, format_summary

    _check_duration(args.duration)
    if args.summary_json is not None:
        check_output(args.summary_json, "--summary-json", inputs=[args.config])
    _check_plot(args)
    if args.socket is not None:  # before anything is created (log, shared memory, socket)
        from hofto_hw.control_plane.process import check_socket_path
        from hofto_hw.control_plane.stop_server import check_stop_path

        args.socket = check_socket_path(args.socket)
        check_stop_path(args.socket)  # <socket>.stop, the stop socket, by the same rules
    with signals.deferred():  # a helper started is one we know (and end)
        helpers.start(
            log=not args.no_log,
            control=args.socket is not None or bool(os.environ.get("NOTIFY_SOCKET")),
        )
    progress = StartupProgress()  # from here: seconds on a loaded machine
    recorder = None
    control = None
    system = None
    try:
        progress.phase("reading the config")
        args.config = find_config(args.config)
        cfg = load_config(args.config)
        _check_interface(cfg, args.interface)
        if args.interface is not None and cfg.bus is not None:
            cfg = cfg.model_copy(
                update={"bus": cfg.bus.model_copy(update={"interface": args.interface})}
            )
        duration = args.duration if args.duration is not None else cfg.run.duration
        _check_ticks(duration, cfg.loop.rate_hz, args.duration is not None)
        clock = args.clock or cfg.run.clock
        lc = cfg.loop
        progress.phase("loading the native dynamics")
        acceleration.require(lc.acceleration, str(args.config))
        latency = lc.cpu_latency_us if clock != "sim" else None  # the sim clock never sleeps
        if clock == "sim" and lc.realtime != "required":
            rt_text = "real-time not used with the sim clock"  # nothing to set up or warn about
        else:
            rt = realtime.setup(lc.realtime, lc.priority, lc.cpus, latency)
            rt_text = rt.describe() if lc.realtime != "off" else "real-time off"
        if clock == "sim" and lc.realtime == "required":
            realtime.drop_realtime()  # back-to-back ticks must not starve the machine
            rt_text += "; checked, then normal priority for the sim clock"
        if cfg.bus is not None and cfg.bus.transport != "sim":
            progress.phase("compiling the tick on the simulated arm, before the bus opens")
            _compile_first(cfg)
        if args.no_log and cfg.run.live_view is not None:
            print("hofto-hw run: run.live_view is off with --no-log (the log's writer serves it)",
                  file=sys.stderr)  # fmt: skip
        if not args.no_log:
            progress.phase("starting the flight recorder")
            with signals.deferred():  # its writer process, closed below once it is ours
                recorder = helpers.recorder = _start_recorder(cfg, args, helpers.writer)
        # Real buses with logs only: the simulated plant starts at its configured pose on every
        # run, and the state file lives beside the logs (--no-log: neither checked nor written).
        positions = None
        if cfg.bus is not None and str(cfg.bus.transport) != "sim" and not args.no_log:
            positions = state_path(args.log_dir or _log_dir(cfg, args.config))
        if args.socket is not None or os.environ.get("NOTIFY_SOCKET"):
            progress.phase("starting the control plane")
        with signals.deferred():  # its process and socket, closed below once they are ours
            control = helpers.plane = _start_control_plane(cfg, args, recorder, helpers.control)
        system = build(
            cfg,
            clock=clock,
            sink=recorder,
            contact=not args.no_collision,
            positions=positions,
            progress=progress.phase,
            before_bus=lambda: helpers.await_ready(progress.phase),
        )
        tick = system.tick

        def _on_signal(signum: int, frame: object) -> None:
            tick.stop_requested = True
            tick.exit_requested = True

        signals.hand_over(_on_signal)  # from here the loop stops the arm (category 1)
        system.acceleration = acceleration.report(system)
        if lc.acceleration == "required" and not system.acceleration["compiled"]:
            raise ConfigError(
                f"{args.config}: loop.acceleration: required, but the tick runs the Python "
                f"reference ({system.acceleration['why']})"
            )
    except BaseException:
        progress.done(started=False)
        from hofto_hw.runtime import realtime

        realtime.drop_realtime()
        if system is not None:  # a stop or failure after the drives were set up
            try:
                system.close()
            except Exception as exc:  # the first error is the one raised; the rest still closes
                print(f"hofto-hw run: closing the bus: {exc}", file=sys.stderr)
        if control is not None:
            control.close(timeout=2.0)
            if args.socket is not None:
                remove_socket(args.socket)
        if recorder is not None:
            recorder.close()
        raise
    if control is not None:  # it also watches the flight recorder (a safety input)
        control.attach(system, watch_log=recorder is not None)
    watch = None
    if recorder is not None and control is None:
        from hofto_hw.runtime.log_watch import LogWatch

        watch = LogWatch(recorder, tick).start()
    if not args.hold and cfg.run.path is not None:
        tick.mode_request = MOVE  # the demo path; without one the arm holds until asked
    n_ticks = None if duration is None else round(duration * system.rate_hz)
    progress.done()
    print(f"hofto-hw run: {_observer_choice(cfg)}", file=sys.stderr)
    for note in tick.group.feedforward_notes():  # drives without 0x60B2 (the loop runs CSP)
        print(f"hofto-hw run: {note}", file=sys.stderr)
    for note in tick.group.settings_notes:  # drives without 0x6072, 0x6065, ... (configure)
        print(f"hofto-hw run: {note}", file=sys.stderr)
    print(
        f"hofto-hw run: running (pid {os.getpid()}; tick: "
        f"{acceleration.describe(system.acceleration)})",
        file=sys.stderr,
        flush=True,
    )
    try:
        run_loop(system, n_ticks, lambda: tick.exit_requested and tick.stopped_and_off())
    finally:
        realtime.drop_realtime()
        signals.restore()
        if control is not None:
            control.close()  # saves a taught path still being recorded
            if args.socket is not None:
                remove_socket(args.socket)
        from hofto_hw.runtime.teach import save_finished

        saved = save_finished(tick, at_end=True)  # a drag --record still open at the end
        if saved:
            print(f"hofto-hw run: {saved}", file=sys.stderr)
        last = _last_positions(system) if positions is not None else None
        system.close()
        if positions is not None:
            _save_positions(positions, last)
        if watch is not None:
            watch.stop()
        health = recorder.close() if recorder is not None else None
    log = None
    if health is not None:
        log = str(health.current_file or recorder.spec.path)
        if health.dropped or health.records_lost or health.write_errors:
            print(
                f"hofto-hw run: flight recorder: {health.dropped} records dropped (ring full), "
                f"{health.records_lost} lost, {health.write_errors} write errors",
                file=sys.stderr,
            )
    summary = build_summary(system, log, rt_text)
    print(format_summary(summary))
    if args.summary_json is not None:  # after the summary is shown: a failure loses no figure
        write_atomic(args.summary_json, json.dumps(summary, indent=2) + "\n", "the summary")
    sys.stdout.flush()
    if args.plot is not None and health is not None:
        from hofto_hw.replay.run_plot import plot_run

        plot_run(Path(log), args.plot)  # type: ignore[arg-type]
        print(f"plot: {args.plot}")
    return 0


def _check_plot(args: argparse.Namespace) -> None:
    """--plot draws the run from its flight log: refused without one, or onto an input."""
    from hofto_hw.commands.args import refuse_overwrite
    from hofto_hw.errors import UserError

    if args.plot is not None and args.no_log:
        raise UserError("--plot: draws the run from its flight log; drop --no-log")
    refuse_overwrite(args.plot, [args.config, args.summary_json], "--plot")


def _last_positions(system: object) -> object:
    """The joint positions to remember (issue 28), read before the drives are disabled."""
    from hofto_hw.runtime.positions import LastPositions

    g, cfg = system.group, system.cfg  # type: ignore[attr-defined]
    return LastPositions(
        list(cfg.robot.joints),
        g.q.copy(),
        [int(z) for z in g.scaling.zero_offset],  # as the loop ran (zero set may move them)
        at_rest=bool(abs(g.qd).max() < 1e-2),
        latched=list(system.tick.stop.latched_names()),  # type: ignore[attr-defined]
    )


def _save_positions(path: Path, last: object) -> None:
    """Write the positions file beside the logs; a failure is reported, not fatal."""
    from hofto_hw.runtime.positions import save_positions

    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        save_positions(path, last)  # type: ignore[arg-type]
    except OSError as exc:
        print(f"hofto-hw run: {path}: positions not saved: {exc.strerror}", file=sys.stderr)


def _start_control_plane(
    cfg: object, args: argparse.Namespace, recorder: object, process: object = None
):
    """The control plane's process (control socket, planning, sd_notify) when the run serves
    a socket or runs under systemd, sent its arguments (``process``: started already,
    runtime.startup.Helpers); None otherwise. Not awaited: ``Helpers.await_ready``."""
    notify = bool(os.environ.get("NOTIFY_SOCKET"))
    if args.socket is None and not notify:
        return None
    from hofto_hw.control_plane.process import ControlPlaneProcess, listen
    from hofto_hw.control_plane.process import remove_socket as remove_one
    from hofto_hw.control_plane.protocol import stop_path
    from hofto_hw.runtime.compose import loop_observer_names

    listener = stop_listener = None
    if args.socket is not None:
        mode = cfg.service.socket_mode  # type: ignore[attr-defined]
        listener = listen(args.socket, mode)
        try:  # the stop socket: served by a process of its own (stop_server.py)
            stop_listener = listen(stop_path(args.socket), mode)
        except BaseException:  # not ours there: only the control socket goes
            listener.close()
            remove_one(args.socket)
            raise
    info = None
    log_path = None
    if recorder is not None:
        name = recorder.shm_name  # type: ignore[attr-defined]
        caps = recorder.caps  # type: ignore[attr-defined]
        info = {"shm": name, "caps": [caps.tick, caps.event, caps.diag]}
        log_path = str(recorder.spec.path)  # type: ignore[attr-defined]
    if args.log_dir is not None:  # the control plane logs zero set beside the logs
        run = cfg.run.model_copy(update={"log_dir": args.log_dir.resolve()})  # type: ignore[attr-defined]
        cfg = cfg.model_copy(update={"run": run})  # type: ignore[attr-defined]
    try:
        control = ControlPlaneProcess(
            cfg,
            args.config,
            listener,
            observers=loop_observer_names(cfg),  # type: ignore[arg-type]
            log_path=log_path,
            recorder=info,
            notify=notify,
            process=process,  # type: ignore[arg-type]
            stop_listener=stop_listener,
        )
    except BaseException:
        if args.socket is not None:
            remove_socket(args.socket)
        raise
    return control


def _compile_first(cfg: Any) -> None:
    """Build (and close) the system once on the simulated arm: every kernel the tick runs is
    compiled or loaded from numba's cache before a real bus opens. Between opening a bus and
    enabling its drives the master exchanges no process data; a cold cache's ~10-60 s of
    compiling there outlasts the drives' watchdog (EtherCAT SM watchdog), they leave OP, and
    enabling fails (found by tests/test_install.py on a first start). Warm: ~1 s."""
    from hofto_hw.runtime.compose import build

    sim = cfg.model_copy(update={"bus": cfg.bus.model_copy(update={"transport": "sim"})})
    build(sim, clock="sim", contact=False).close()


def _start_recorder(cfg: object, args: argparse.Namespace, writer: object = None) -> object:
    """The MCAP flight recorder for this run's log file, its writer process (``writer``:
    started already, runtime.startup.Helpers) sent its arguments; not awaited
    (``Helpers.await_ready``)."""
    from hofto_hw import jit
    from hofto_hw.commands.backend import observer_backend
    from hofto_hw.errors import UserError
    from hofto_hw.recording.attachments import run_attachments, run_metadata
    from hofto_hw.recording.log_spec import LogSpec
    from hofto_hw.recording.recorder import FlightRecorder
    from hofto_hw.runtime import acceleration
    from hofto_hw.runtime.compose import loop_observer_names
    from safety.stop import EVENT_NAMES

    folder = args.log_dir or _log_dir(cfg, args.config)
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UserError(f"run.log_dir: cannot create {folder}: {exc.strerror}") from None
    names = loop_observer_names(cfg)  # type: ignore[arg-type]
    spec = LogSpec(
        path=folder / f"run-{time.strftime('%Y%m%d-%H%M%S')}-{os.getpid()}.mcap",
        joint_names=list(cfg.robot.joints),  # type: ignore[attr-defined]
        observers=names,
        attachments=run_attachments(args.config, cfg),  # type: ignore[arg-type]
        metadata={
            **run_metadata(args.config, cfg, names[0]),  # type: ignore[arg-type]
            "observer_backend": jit.resolve(observer_backend()),
            "acceleration": acceleration.missing() or "compiled",  # else why not
        },
        event_kinds=dict(EVENT_NAMES),
        tool_frame=cfg.robot.tool_frame,  # type: ignore[attr-defined]
        live_view=_live_spec(cfg.run.live_view),  # type: ignore[attr-defined]
    )
    recorder = FlightRecorder(spec, writer=writer).start(wait=False)  # type: ignore[arg-type]
    for name, size, pid in recorder.removed_stale:
        print(
            f"hofto-hw run: removed stale shared memory /dev/shm/{name} ({size / 1e6:.1f} MB, "
            f"its run, pid {pid}, is gone)",
            file=sys.stderr,
        )
    return recorder


def _live_spec(live: object) -> object:
    """run.live_view as the writer's LiveSpec (None: off)."""
    if live is None:
        return None
    from hofto_hw.recording.live import LiveSpec

    return LiveSpec(live.host, live.port, live.rate_hz)  # type: ignore[attr-defined]


def _log_dir(cfg: object, config_path: Path) -> Path:
    from hofto_hw.config.locate import output_folder

    return output_folder(cfg.run.log_dir, config_path)  # type: ignore[attr-defined]
