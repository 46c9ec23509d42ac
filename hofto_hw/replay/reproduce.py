"""Re-run a flight log's observers and collision monitor and check the recorded decision.

The robot, its observers and the thresholds come from the log's attachments (config, URDF,
parameters, thresholds files; see hofto_hw.recording.attachments), the measurements from
/joint_states, dt from consecutive stamps. The run's collision decision is reproduced when
the monitor, fed the re-computed estimate of the recorded detector observer, first detects
in the same tick as the first recorded collision event (and on that event's joint).

Bit-exact reproduction needs the loop to do what replay does: t from integer nanoseconds
(the stamp stores t exactly then), dt = t[k] - t[k-1], observers reset on the first tick's
q, qd and updated from the second. ``max_abs_diff`` per observer shows whether they did.

What a client changed while the run went on is replayed at its tick, as the loop took it
(between that tick and the next): a safety profile switch (``profile`` event: the collision
thresholds scaled by its value from the next tick on; the run's first profile is the config's
``safety.profiles.active``) and a payload (``payload`` events: the observers' model carries it
from the next tick on).

:func:`make_detector` is the single place that builds the monitor from the recorded config:
the two-level monitor of the service branch plugs in there.
"""

from __future__ import annotations

import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from hofto_hw import jit
from hofto_hw.config.loader import parse_config, parse_yaml_bytes
from hofto_hw.config.models import ObserverConfig, SystemConfig
from hofto_hw.errors import ConfigError, UserError
from hofto_hw.identify.data import Recording
from hofto_hw.model import RobotModel
from hofto_hw.observers import make_observer
from hofto_hw.recording import attachments as att
from hofto_hw.replay.flight_log import FlightLog, RecordedEvent
from hofto_hw.replay.runner import run_observer
from hofto_hw.replay.thresholds import ThresholdsFile, read_thresholds
from hofto_hw.runtime.compose import build_model, loop_observer_table
from hofto_hw.runtime.tick_kernels import gap_steps, lerp

#: event kind name of a collision stop (the safety fault class's name in event_kinds)
COLLISION_KIND = "collision"
RESET_KIND = "reset"  # the loop resets its observers on the state of the tick it resets in
PROFILE_KIND = "profile"  # a safety profile switch (value: its collision scale)
PAYLOAD_KIND = "payload"  # a payload set at run time (joint -1: mass; 0, 1, 2: com)


class Monitor(Protocol):
    """What replay needs of a collision monitor (safety.collision.CollisionMonitor)."""

    joints: np.ndarray

    def reset(self, qd: np.ndarray | None = None) -> None: ...

    def update(self, tau_ext: np.ndarray, qd: np.ndarray, dt: float) -> bool: ...


@dataclass
class RunSetup:
    """The recorded run rebuilt: config, model, thresholds (None when not attached), and the
    model the loop of `hofto-hw run` used (with the configured payload)."""

    config: SystemConfig
    model: RobotModel
    thresholds: ThresholdsFile | None
    loop_model: RobotModel | None = None


@dataclass
class Detector:
    """The recorded detector: which observer's estimate feeds which monitor."""

    observer: str
    monitor: Monitor


@dataclass
class Reproduction:
    """Outcome: recorded vs replayed first collision tick/joints, per-observer max |Δ|."""

    detector: str
    recorded: RecordedEvent | None
    replayed_tick: int | None
    replayed_joints: list[int]
    max_abs_diff: dict[str, float] = field(default_factory=dict)
    #: observer name -> replayed estimate (N, n) [N·m] (for the figure of `replay --plot`)
    replayed: dict[str, np.ndarray] = field(default_factory=dict, repr=False)

    @property
    def match(self) -> bool:
        if self.recorded is None:
            return self.replayed_tick is None
        same_tick = self.replayed_tick == self.recorded.tick
        joint = self.recorded.joint
        return same_tick and (joint < 0 or joint in self.replayed_joints)

    def as_dict(self) -> dict[str, Any]:
        rec = self.recorded
        return {
            "detector": self.detector,
            "recorded": None
            if rec is None
            else {
                "tick": rec.tick,
                "t": rec.t,
                "joint": rec.joint,
                "category": rec.category,
            },
            "replayed": {"tick": self.replayed_tick, "joints": self.replayed_joints},
            "match": self.match,
            "max_abs_diff": self.max_abs_diff,
        }


def run_setup(log: FlightLog) -> RunSetup:
    """Config, model and thresholds from the log's attachments."""
    files = log.attachments
    if att.CONFIG not in files or att.URDF not in files:
        raise UserError(
            f"{log.path}: no {att.CONFIG}/{att.URDF} attachments: cannot rebuild the robot"
        )
    src = f"{log.path}:{att.CONFIG}"
    data = parse_yaml_bytes(files[att.CONFIG], src, "config file")
    if not isinstance(data.get("robot"), dict):
        raise ConfigError(f"{src}: no robot section")
    with tempfile.TemporaryDirectory(prefix="hofto-replay-") as tmp:
        folder = Path(tmp)
        for name in (att.URDF, att.PARAMETERS, att.THRESHOLDS):
            if name in files:
                (folder / name).write_bytes(files[name])
        data["robot"]["urdf"] = att.URDF
        data["robot"]["parameters"] = att.PARAMETERS if att.PARAMETERS in files else None
        cfg = parse_config(data, source=src, base_dir=folder)
        model = RobotModel.from_config(cfg.robot)
        loop = build_model(cfg)
        thresholds = read_thresholds(folder / att.THRESHOLDS) if att.THRESHOLDS in files else None
    if model.n != len(log.joint_names):
        raise UserError(f"{log.path}: {len(log.joint_names)} joints, its robot has {model.n}")
    return RunSetup(cfg, model, thresholds, loop)


def observer_config(setup: RunSetup, name: str, path: Path) -> ObserverConfig:
    """Observer ``name`` as the run's config defines it (else as the thresholds file does)."""
    if name in setup.config.observers:
        return setup.config.observers[name]
    th = setup.thresholds
    if th is not None and name in th.observers:
        return th.observers[name].observer
    raise UserError(f"{path}: observer {name!r} is in the log but not in its config")


def make_detector(log: FlightLog, setup: RunSetup) -> Detector:
    """The monitor the run used, built from the recorded config: the ``detector`` observer
    (metadata) with its thresholds-file monitor; else, for logs of ``hofto-hw run`` (which
    record ``monitored`` and ``qdd_cmd``), the two-level CollisionLevels of
    ``safety.collision`` over every loop observer; else the config's ``collision`` section."""
    from safety.collision import CollisionLevels, CollisionMonitor

    name = log.metadata.get("detector") or (log.observers[0] if log.observers else "")
    th = setup.thresholds
    if th is not None and name in th.observers:
        return Detector(name, CollisionMonitor(th.observers[name].monitor))
    levels_cfg = setup.config.safety.collision
    if levels_cfg is not None and log.monitored is not None:
        try:
            levels = CollisionLevels(
                levels_cfg, log.observers, loop_model(setup), backend=recorded_backend(log)
            )
        except ValueError as exc:
            raise UserError(f"{log.path}: safety.collision: {exc}") from None
        prof = setup.config.safety.profiles
        if prof is not None:  # the run started with the active profile's thresholds
            levels.scale_thresholds(prof.sets[prof.active].collision_scale)
        return Detector(levels_cfg.observer, levels)
    if setup.config.collision is not None:
        return Detector(name, CollisionMonitor(setup.config.collision))
    raise UserError(f"{log.path}: no thresholds for detector {name!r} in the attached files")


def loop_model(setup: RunSetup) -> RobotModel:
    """The model the loop ran: the identified one with the configured payload."""
    assert setup.loop_model is not None
    return setup.loop_model


def loop_dt(log: FlightLog, rate_hz: float) -> np.ndarray:
    """dt (N,) [s] as the loop handed it to the tick: whole periods of 1/rate since the last
    tick (dt[0] = one period; the loop's t is the sum of these, so stamps round to them)."""
    period = float(np.int64(round(1e9 / rate_hz))) * 1e-9
    periods = np.ones(log.n_ticks)
    periods[1:] = np.maximum(1.0, np.round(np.diff(log.t) / period))
    return periods * period


def replay_levels(
    levels: Any, cfg: SystemConfig, estimates: np.ndarray, log: FlightLog, dt: np.ndarray
) -> tuple[int | None, list[int]]:
    """First tick (index) CollisionLevels decides a collision on ``estimates`` (N, k, n),
    judged only on the ticks the run judged (``monitored``), and its joints; over the
    observers' interval where the log has it (``sample_dt``), as the loop did."""
    from safety.collision import COLLIDED
    from safety.stop import StopController

    assert log.monitored is not None and log.qdd_cmd is not None
    stop = StopController.from_config(cfg.safety.categories)
    levels.reset()
    h = dt if log.sample_dt is None else np.where(log.sample_dt > 0.0, log.sample_dt, dt)
    switches = profile_switches(log)
    for k in range(log.n_ticks):
        if log.monitored[k]:
            stop.begin_tick(int(log.ticks[k]))
            qdd = log.qdd_cmd[k]
            if levels.update(stop, estimates[k], log.q[k], log.qd[k], qdd, h[k]) & COLLIDED:
                return k, [int(j) for j in np.flatnonzero(levels.collision_joints)]
        while switches and switches[0][0] <= log.ticks[k]:  # taken after that tick
            levels.scale_thresholds(switches.pop(0)[1])
    return None, []


def profile_switches(log: FlightLog) -> list[tuple[int, float]]:
    """The run's safety profile switches: (tick, collision scale), in tick order."""
    return sorted((e.tick, e.value) for e in log.events if e.kind_name == PROFILE_KIND)


def payload_changes(log: FlightLog) -> list[tuple[int, Any]]:
    """The payloads a client set during the run: (tick, hofto_hw.model.payload.Payload), in
    tick order (each one four events of its tick: the mass, then the com's x, y, z)."""
    from hofto_hw.model.payload import Payload

    out: list[tuple[int, Any]] = []
    parts: dict[int, list[float]] = {}
    for e in sorted(
        (e for e in log.events if e.kind_name == PAYLOAD_KIND), key=lambda e: (e.tick, e.joint)
    ):
        if e.joint == -1:
            parts[e.tick] = [e.value, 0.0, 0.0, 0.0]
        elif e.tick in parts and 0 <= e.joint < 3:
            parts[e.tick][1 + e.joint] = e.value
    for tick, (m, x, y, z) in sorted(parts.items()):
        out.append((tick, Payload(m, (x, y, z))))
    return out


class _PayloadReplay:
    """Swaps the recorded payloads into an observer's own model at their ticks (the loop's
    LinkSwap, with the numbers the control plane computed: the same arithmetic)."""

    def __init__(self, model: Any, changes: list[tuple[int, Any]]) -> None:
        from hofto_hw.model.payload import LinkSwap, bare_link

        self.model = model
        self.changes = list(changes)
        self.bare = bare_link(model) if changes else None
        self.swap = LinkSwap(model) if changes else None

    def after(self, tick: int) -> None:
        """The loop's tick ``tick`` ended: the payloads set in it from now on."""
        from hofto_hw.model.payload import link_numbers

        while self.changes and self.changes[0][0] <= tick:
            _, p = self.changes.pop(0)
            assert self.swap is not None
            np.copyto(self.swap.values, link_numbers(self.model, self.bare, p))
            self.swap.apply(p)


def as_recording(log: FlightLog) -> Recording:
    return Recording(
        t=log.t,
        q=log.q,
        qd=log.qd,
        tau=log.tau,
        source=str(log.path),
        rows=np.arange(1, log.n_ticks + 1, dtype=np.int64),
    )


def first_detection(
    monitor: Monitor, tau_ext: np.ndarray, log: FlightLog
) -> tuple[int | None, list[int]]:
    """Index of the first tick the monitor detects on ``tau_ext`` (N, n), and its joints."""
    qd, t = log.qd, log.t
    monitor.reset(qd[0])
    for k in range(1, log.n_ticks):
        if monitor.update(tau_ext[k], qd[k], t[k] - t[k - 1]):
            return k, [int(j) for j in np.flatnonzero(monitor.joints)]
    return None, []


def recorded_backend(log: FlightLog) -> jit.Backend:
    """The observer implementation the run used (metadata ``observer_backend``; numpy when
    absent): the same arithmetic is what makes the replay bit-exact. A run on the compiled
    kernels replays on them; without numba here it falls back to numpy (then to ~1e-11)."""
    return "auto" if log.metadata.get("observer_backend") == "numba" else "python"


def reproduce(log: FlightLog, detector_factory=make_detector) -> Reproduction:
    """Replay every recorded observer and the detector's monitor; compare with the log."""
    from safety.collision import CollisionLevels

    setup = run_setup(log)
    det = detector_factory(log, setup)
    levels = isinstance(det.monitor, CollisionLevels)
    dt = loop_dt(log, float(setup.config.loop.rate_hz)) if levels else None
    model = loop_model(setup) if levels else setup.model
    replayed: dict[str, np.ndarray] = {}
    diffs: dict[str, float] = {}
    for name in log.observers:
        if levels:
            table = loop_observer_table(setup.config)
            if name not in table:
                raise UserError(f"{log.path}: observer {name!r} is not in its config's loop")
            ocfg = table[name]
        else:
            ocfg = observer_config(setup, name, log.path)
        changes = payload_changes(log) if dt is not None else []
        own = model.copy() if changes else model  # each observer's payloads from the start
        obs = make_observer(ocfg, own, backend=recorded_backend(log))
        replayed[name] = (
            run_observer(as_recording(log), obs)
            if dt is None
            else _run_with_dt(
                obs, log, dt, 1.0 / float(setup.config.loop.rate_hz), _PayloadReplay(own, changes)
            )
        )
        diffs[name] = float(np.max(np.abs(replayed[name] - log.tau_ext[name])))
    if levels:
        est = np.stack([replayed[o] for o in log.observers], axis=1)
        k, joints = replay_levels(det.monitor, setup.config, est, log, dt)
    else:
        if det.observer not in replayed:
            raise UserError(f"{log.path}: detector observer {det.observer!r} was not recorded")
        k, joints = first_detection(det.monitor, replayed[det.observer], log)
    collisions = [e for e in log.events if e.kind_name == COLLISION_KIND]
    return Reproduction(
        detector=det.observer,
        recorded=collisions[0] if collisions else None,
        replayed_tick=None if k is None else int(log.ticks[k]),
        replayed_joints=joints,
        max_abs_diff=diffs,
        replayed=replayed,
    )


def _run_with_dt(
    obs: Any, log: FlightLog, dt: np.ndarray, period: float = 0.0, payloads: Any = None
) -> np.ndarray:
    """Estimates (N, n) as the loop computes them: reset, then updated on every tick with the
    loop's dt. The loop resets on the state read just before its first tick, which is not
    recorded: it is taken one period back along the first tick's velocity (q0 - qd0·dt0,
    qd0), so that the first update predicts onto the first sample as the loop's does. A
    high-gain observer reset on the first sample itself starts from an error of qd0·dt0 and
    its estimate jumps (HOFTO with poles at -300 rad/s: -8.6 N·m on joint 2 in tick 1, where
    the loop had -0.14); the starts differ by < 1e-6 N·m after 50 ticks either way.

    A stall (a tick more than 1.5 periods after the last) is integrated in one-cycle steps
    over the interpolated samples, as the loop does (``gap_steps``).

    A reset of the stop controller (a ``reset`` event) also resets the loop's observers on
    that tick's measured state after their update; replay does the same, so the estimates
    after a reset are the loop's too.

    Logs that record the observers' own interval per tick (``sample_dt``: the drives' sample
    interval with EtherCAT DC, 0 where the loop held its observers over a lost sample) are
    integrated over it instead of ``dt``; a held tick keeps the last estimate, and the next
    gap is interpolated from the last sample the observers took, as the loop does.

    ``payloads`` (:class:`_PayloadReplay` of the observer's own model): the payloads a client
    set, swapped in after the tick they were set in, as the loop took them."""
    h_obs = dt if log.sample_dt is None else log.sample_dt
    est = np.zeros_like(log.q)
    index = {int(tk): k for k, tk in enumerate(log.ticks)}
    resets = {index[e.tick] for e in log.events if e.kind_name == RESET_KIND and e.tick in index}
    h0 = float(h_obs[0]) if h_obs[0] > 0.0 else float(dt[0])
    obs.reset(log.q[0] - log.qd[0] * h0, log.qd[0])
    x = np.zeros((3, log.q.shape[1]))
    last = 0  # the tick of the last sample the observers took
    for k in range(log.n_ticks):
        hk = float(h_obs[k])
        steps = gap_steps(hk, period) if k > 0 else 1
        if hk <= 0.0:  # held over a lost sample: the loop did not update its observers
            est[k] = est[k - 1] if k > 0 else 0.0
        elif steps == 1:
            est[k] = obs.update(log.q[k], log.qd[k], log.tau[k], hk)
            last = k
        else:  # a stall: the loop integrated the gap in one-cycle steps (tick_kernels.gap_steps)
            h = hk / steps
            for s in range(1, steps + 1):
                a = s / steps
                for j, series in enumerate((log.q, log.qd, log.tau)):
                    lerp(series[last], series[k], a, x[j])
                est[k] = obs.update(x[0], x[1], x[2], h)
            last = k
        if k in resets:
            obs.reset(log.q[k], log.qd[k])
        if payloads is not None:
            payloads.after(int(log.ticks[k]))
    return est
