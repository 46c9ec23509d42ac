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
    parser.add_argument("--no-collision", action="store_true", help="no scripted collision")
    parser.add_argument(
        "--socket", type=Path, default=None, help="serve the control socket at this path"
    )
    parser.add_argument("--hold", action="store_true", help="start in hold, not move")
    parser.add_argument(
        "--interface", default=None, help="bus.interface override (NIC for ethercat, CAN channel)"
    )


def _check_duration(value: float | None) -> None:
    from hofto_hw.errors import UserError

    if value is not None and (not math.isfinite(value) or value <= 0.0):
        raise UserError(f"--duration: must be a finite number of seconds > 0, got {value}")


def _check_output(path: Path | None, what: str) -> None:
    from hofto_hw.errors import UserError

    if path is not None and path.is_dir():
        raise UserError(f"{what}: {path} is a directory, expected a file name")


def run(args: argparse.Namespace) -> int:
    from hofto_hw.runtime.startup import StartupProgress

    _check_duration(args.duration)
    _check_output(args.summary_json, "--summary-json")
    progress = StartupProgress()  # from here: the imports take seconds on a loaded machine
    recorder = None
    try:
        progress.phase("importing numpy, pinocchio, numba")
        from hofto_hw.config import load_config
        from hofto_hw.config.locate import find_config
        from hofto_hw.control.joint_motion import MOVE
        from hofto_hw.errors import ConfigError
        from hofto_hw.runtime import acceleration, realtime
        from hofto_hw.runtime.compose import build
        from hofto_hw.runtime.drag_script import run_loop
        from hofto_hw.runtime.summary import build_summary, format_summary

        progress.phase("reading the config")
        args.config = find_config(args.config)
        cfg = load_config(args.config)
        if args.interface is not None and cfg.bus is not None:
            cfg = cfg.model_copy(
                update={"bus": cfg.bus.model_copy(update={"interface": args.interface})}
            )
        duration = args.duration if args.duration is not None else cfg.run.duration
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
        if not args.no_log:
            progress.phase("starting the flight recorder")
            recorder = _start_recorder(cfg, args)
        system = build(
            cfg,
            clock=clock,
            sink=recorder,
            contact=not args.no_collision,
            progress=progress.phase,
        )
        system.acceleration = acceleration.report(system)
        if lc.acceleration == "required" and not system.acceleration["compiled"]:
            system.close()
            raise ConfigError(
                f"{args.config}: loop.acceleration: required, but the tick runs the Python "
                f"reference ({system.acceleration['why']})"
            )
    except BaseException:
        progress.done()
        from hofto_hw.runtime import realtime

        realtime.drop_realtime()
        if recorder is not None:
            recorder.close()
        raise
    tick = system.tick

    def _on_signal(signum: int, frame: object) -> None:
        tick.stop_requested = True
        tick.exit_requested = True

    old = {s: signal.signal(s, _on_signal) for s in (signal.SIGTERM, signal.SIGINT)}
    service = None
    if args.socket is not None:
        from hofto_hw.runtime.service import ControlServer

        service = ControlServer(args.socket, system, mode=cfg.service.socket_mode)
        service.start()
    supervisor = None
    if os.environ.get("NOTIFY_SOCKET"):
        from hofto_hw.runtime.service import Supervisor

        supervisor = Supervisor(system, cfg.service.watchdog_fraction, cfg.service.status_interval)
        supervisor.start()
    watch = None
    if recorder is not None:
        from hofto_hw.runtime.log_watch import LogWatch

        watch = LogWatch(recorder, tick).start()
    if not args.hold and cfg.run.path is not None:
        tick.mode_request = MOVE  # the demo path; without one the arm holds until asked
    n_ticks = None if duration is None else round(duration * system.rate_hz)
    progress.done()
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
        for s, h in old.items():
            signal.signal(s, h)
        if service is not None:
            service.close()
        from hofto_hw.runtime.teach import save_finished

        saved = save_finished(tick, at_end=True)  # a drag --record still open at the end
        if saved:
            print(f"hofto-hw run: {saved}", file=sys.stderr)
        system.close()
        if watch is not None:
            watch.stop()
        health = recorder.close() if recorder is not None else None
        if supervisor is not None:
            supervisor.stop()
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
    if args.summary_json is not None:
        args.summary_json.parent.mkdir(parents=True, exist_ok=True)
        args.summary_json.write_text(json.dumps(summary, indent=2) + "\n")
    print(format_summary(summary))
    sys.stdout.flush()
    return 0


def _compile_first(cfg: Any) -> None:
    """Build (and close) the system once on the simulated arm: every kernel the tick runs is
    compiled or loaded from numba's cache before a real bus opens. Between opening a bus and
    enabling its drives the master exchanges no process data; a cold cache's ~10-60 s of
    compiling there outlasts the drives' watchdog (EtherCAT SM watchdog), they leave OP, and
    enabling fails (found by tests/test_install.py on a first start). Warm: ~1 s."""
    from hofto_hw.runtime.compose import build

    sim = cfg.model_copy(update={"bus": cfg.bus.model_copy(update={"transport": "sim"})})
    build(sim, clock="sim", contact=False).close()


def _start_recorder(cfg: object, args: argparse.Namespace) -> object:
    """The MCAP flight recorder (its writer process started) for this run's log file."""
    from hofto_hw.commands.backend import observer_backend
    from hofto_hw.errors import UserError
    from hofto_hw.observers import kernels
    from hofto_hw.recording.attachments import run_attachments, run_metadata
    from hofto_hw.recording.flight_file import LogSpec
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
            "observer_backend": kernels.resolve(observer_backend()),
            "acceleration": acceleration.missing() or "compiled",  # else why not
        },
        event_kinds=dict(EVENT_NAMES),
    )
    return FlightRecorder(spec).start()


def _log_dir(cfg: object, config_path: Path) -> Path:
    d = cfg.run.log_dir  # type: ignore[attr-defined]
    return d if d.is_absolute() else (config_path.resolve().parent / d).resolve()
