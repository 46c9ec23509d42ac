"""Composition root of ``hofto-hw run``: config -> model, bus, drives, observers, safety,
controller, tick, loop. The only place that knows how the parts fit together.

The simulated bus comes from :func:`hofto_hw.runtime.build.build_sim_bus`; every observer is
checked for discrete-time stability at ``loop.rate_hz`` before it is built, and every model
consumer owns its workspace (``model.create_data()``).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from drivers.cia402.brake import ReleaseCheck
from drivers.cia402.drive_group import DriveGroup
from drivers.cia402.state_machine import Mode, State
from drivers.sim.simbus import SimBus
from drivers.transport import Transport
from hofto_hw.commands.backend import observer_backend
from hofto_hw.config.models import ExternalTorqueConfig, SystemConfig
from hofto_hw.control.drag import DragController
from hofto_hw.control.enabling import EnableInput
from hofto_hw.control.friction_residual import FrictionResidual
from hofto_hw.control.joint_motion import DemoPath, JointMotion
from hofto_hw.errors import ConfigError
from hofto_hw.jit import Backend
from hofto_hw.model.data import ModelData
from hofto_hw.model.payload import apply_payload, payload_from_config
from hofto_hw.model.robot import RobotModel
from hofto_hw.model.snapshot import DynamicsSnapshot, Needs
from hofto_hw.observers import make_observer
from hofto_hw.observers.base import Observer
from hofto_hw.observers.stability import check_observer
from hofto_hw.recording.record import MemorySink, RecordSink, tick_dtype
from hofto_hw.runtime.build import (
    apply_true_load,
    build_drive_group,
    build_sim_bus,
    build_transport,
)
from hofto_hw.runtime.fused import hot_record, tick_state_dtype
from hofto_hw.runtime.loop import Loop, RealClock, SimClock
from hofto_hw.runtime.motion_check import check_motion
from hofto_hw.runtime.realtime import collect_before_loop
from hofto_hw.runtime.tick import Tick
from safety.bus_health import BusHealth
from safety.collision import CollisionLevels
from safety.collision.state import MonitorState
from safety.limits import LimitMonitor
from safety.stop import StopController

#: observers the loop runs, in record order (those present in the config)
LOOP_OBSERVERS = ("hofto", "momentum")


@dataclass
class ScriptedContact:
    """The scripted collision of ``run.collision`` in loop terms: onset tick and time."""

    joint: int
    peak: float
    start: float  # [s] loop time of the contact onset
    onset_tick: int  # first tick whose exchange includes the contact


@dataclass
class System:
    """Everything ``hofto-hw run`` drives (built by :func:`build`)."""

    cfg: SystemConfig
    model: RobotModel
    bus: Transport  # SimBus on the simulated bus
    group: DriveGroup
    tick: Tick
    loop: Loop
    clock: RealClock | SimClock
    sink: RecordSink
    rate_hz: float
    contact: ScriptedContact | None = None
    observer_names: list[str] = field(default_factory=list)
    drag_script: Any = None  # hofto_hw.runtime.drag_script.DragScript of run.drag
    acceleration: dict[str, Any] | None = None  # hofto_hw.runtime.acceleration.report

    def close(self) -> None:
        """Stop the drives (category 1 if still powered), disable them, close the bus."""
        shut_down(self.group, self.bus)


def shut_down(group: DriveGroup, bus: Transport) -> None:
    """Stop the drives (category 1 if still powered), disable them, close the bus; nothing
    but the close when the bus is closed already (a failed start-up step closed it)."""
    if not getattr(bus, "is_open", True):
        bus.close()
        return
    try:
        group.cycle()
        if (group.states == State.OPERATION_ENABLED).any():
            group.quick_stop()
        group.disable()
    finally:
        bus.close()


def _sim_config(cfg: SystemConfig) -> SystemConfig:
    """The config the simulated bus is built from: no scripted world torques (the run adds
    its own contact) and the run's model error."""
    if cfg.bus is None:
        raise ConfigError("bus: section missing; hofto-hw run needs the drive data")
    sim = None
    if cfg.simulation is not None:
        update: dict = {"external": []}
        if cfg.run.model_error is not None:
            update["model_error"] = cfg.run.model_error
        sim = cfg.simulation.model_copy(update=update)
    return cfg.model_copy(update={"simulation": sim})


def loop_observer_table(cfg: SystemConfig) -> dict:
    """Observer configs the loop uses: ``loop.observers`` over the top-level ``observers``."""
    return {**cfg.observers, **(cfg.loop.observers or {})}


def loop_observer_names(cfg: SystemConfig) -> list[str]:
    """The observers the loop runs, in record order (rows of ``tau_ext``)."""
    table = loop_observer_table(cfg)
    names = [name for name in LOOP_OBSERVERS if name in table]
    if not names:
        raise ConfigError("observers: hofto-hw run needs 'hofto' and/or 'momentum'")
    return names


def build_model(cfg: SystemConfig) -> RobotModel:
    """The identified model with the configured payload."""
    model = RobotModel.from_config(cfg.robot)
    if cfg.safety.payload.mass > 0.0:
        apply_payload(model, payload_from_config(cfg.safety.payload))
    return model


def shared_snapshot(
    model: RobotModel, observers: list[Observer], hot: dict[str, np.ndarray] | None = None
) -> DynamicsSnapshot:
    """The tick's one dynamics snapshot: the union of the observers' ``needs``, computed with
    the implementation their own snapshots use (the compiled friction and Cᵀ·qd when every
    observer runs compiled, else numpy), so the shared terms equal each observer's own.

    Not shared with the feed-forward (inverse dynamics at the reference motion, another
    sample) nor with the drag controller (Jacobians and frame placements, not snapshot terms).
    """
    needs = Needs.NONE
    compiled = True
    for obs in observers:
        needs |= obs.needs
        own = getattr(obs, "snapshot", None)
        compiled = compiled and own is not None and own.backend == "numba"
    return DynamicsSnapshot(model, needs, "numba" if compiled else "python", hot=hot)


def hot_parts(cfg: SystemConfig, n: int, names: list[str]) -> dict[str, dict[str, np.dtype]]:
    """The fields of the tick's hot record (runtime.fused.hot_record), per part, from each
    part's own ``hot_fields``; an absent part (no collision monitor, no friction learning, no
    demo path) keeps a zeroed field of its type, which the compiled call does not read."""
    k, coll = max(1, len(names)), cfg.safety.collision
    return {
        "tick": {"state": tick_state_dtype(n, k)},
        "group": DriveGroup.hot_fields(n),
        "snap": DynamicsSnapshot.hot_fields(n),
        "ff": ModelData.hot_fields(n),
        "lim": LimitMonitor.hot_fields(n),
        "motion": JointMotion.hot_fields(n),
        "coll": (
            CollisionLevels.hot_fields(coll, names) if coll else MonitorState.hot_fields(1, k, n)
        ),
        "learn": FrictionResidual.hot_fields(n),
        "path": DemoPath.hot_fields(n),
    }


def build(
    cfg: SystemConfig,
    *,
    clock: str = "sim",
    sink: RecordSink | None = None,
    contact: bool = True,
    positions: Path | None = None,
    progress: Callable[[str], None] | None = None,
    before_bus: Callable[[], None] | None = None,
) -> System:
    """Build and start everything: drives enabled in CSP, holding; the loop not yet run.

    ``positions``: the state file of the last clean shutdown (``runtime.positions``); a joint
    read more than half a motor turn away from it is refused before any drive is enabled.

    The drives are enabled last, after every compiled kernel is warmed (seconds when the
    cache is cold): an enabled drive on a bus whose process data stops for longer than its
    watchdog (EtherCAT SM watchdog, 100 ms by default) leaves Operation enabled, and the
    loop's first tick would latch a disabled drive. ``progress(text)`` is told each phase as
    it begins (hofto_hw.runtime.startup). ``before_bus()`` runs once the kernels are loaded,
    before the bus opens: the run awaits its helper processes there (they started before this
    and loaded meanwhile); a wait between opening a real bus and enabling would hold back the
    process data as a compile would."""
    say = progress if progress is not None else _silent
    rate = float(cfg.loop.rate_hz)
    model = build_model(cfg)
    check_motion(cfg, model)  # home and demo path inside the monitored limits
    table = loop_observer_table(cfg)
    names = loop_observer_names(cfg)
    for name in names:
        check_observer(name, table[name], model, rate)
    say("loading the compiled kernels (compiling them when numba's cache is cold)")
    backend = observer_backend()  # compiled kernels when numba is there, warmed here
    observers = [make_observer(table[name], model, backend=backend) for name in names]
    sink = sink if sink is not None else MemorySink(tick_dtype(model.n, len(names)))
    # the tick's one hot record first; each part is built on its fields (no part allocates
    # an array the compiled call reads, nothing is moved afterwards)
    hot, on = hot_record(hot_parts(cfg, model.n, names))
    if before_bus is not None:
        before_bus()

    say("opening the bus")
    bus, group = build_bus(cfg, clock, hot=on["group"])
    try:
        say("loading the safety checks and the tick (compiled code)")

        s = cfg.safety
        stop = StopController.from_config(s.categories)
        limits = LimitMonitor.from_config(s.limits, model.limits, backend, on["lim"])
        health = BusHealth(
            model.n,
            s.bus.lost_cycles,
            int(State.OPERATION_ENABLED),
            (int(State.FAULT_REACTION_ACTIVE), int(State.FAULT), int(State.UNKNOWN)),
            backend=backend,
        )
        collision = None
        if s.collision is not None:
            collision = CollisionLevels(s.collision, names, model, backend, on["coll"])
        if collision is not None and s.profiles is not None:  # the active profile's scale
            collision.scale_thresholds(s.profiles.sets[s.profiles.active].collision_scale)
        accel = np.where(np.isfinite(model.limits.acceleration), model.limits.acceleration, 10.0)
        p = cfg.run.path
        path = None
        if p is not None:
            path = DemoPath(p.amplitude, p.period, p.phase, p.ramp, backend, on["path"])
        motion = JointMotion(model.n, accel, path, backend, on["motion"])
        drag, enable, drag_row = _build_drag(cfg, model, names, backend, on["learn"])
        if drag is not None and s.profiles is not None:  # the active safety profile's drag
            drag.apply_profile(*s.profiles.sets[s.profiles.active].drag_factors())
        tick = Tick(
            group,
            observers,
            shared_snapshot(model, observers, on["snap"]),
            stop,
            limits,
            health,
            collision,
            motion,
            model.create_data(backend, on["ff"]),  # the feed-forward: compiled friction
            sink,
            overrun_limit=s.overrun_streak,
            drag=drag,
            enable_input=enable,
            drag_row=drag_row,
            period=1.0 / rate,
            backend=backend,
            hot=hot,
        )
        tick.diag_every = max(1, round(rate / 10.0))
        # issue 28: STO and brake faults named by the drive layer (their sources: the profiles);
        # the brake release check repeated on every re-enable after a reset
        health.sto_of = group.sto_of
        health.brake_code = group.is_brake_fault
        tick.release_check = ReleaseCheck.from_drives(list(cfg.bus.drives), 1.0 / rate)
        tick.reenable_refused = reenable_refusal(cfg)
        if s.collision is not None:
            tick.settle_ticks = round(s.collision.settle_time * rate)
        if positions is not None:
            check_start_positions(cfg, bus, group, positions)
        braked = preload_braked_axes(cfg, model, group)
        if clock != "sim":
            say("collecting garbage")
            collect_before_loop()  # the loop's own collection then fits inside the bus watchdog
        say("enabling the drives")
        enable_drives(bus, group)
        if braked.size:
            await_brake_release(cfg, bus, group, braked)
        tick.start()
        period_ns = round(1e9 / rate)
        clk: RealClock | SimClock = SimClock(period_ns) if clock == "sim" else RealClock(period_ns)
        loop = Loop(tick, clk)
        simulated = isinstance(bus, SimBus)
        if not clk.sim and simulated:
            loop.data_dt = 1.0 / rate  # SimBus in real time: one plant cycle per exchange
        system = System(cfg, model, bus, group, tick, loop, clk, sink, rate)
        system.observer_names = names
        if contact and simulated and cfg.run.collision is not None:
            system.contact = _script_contact(system)
            if cfg.run.drag is not None and drag is not None:
                from hofto_hw.runtime.drag_script import DragScript

                model_for_replay = model if clk.sim else None  # the replay needs the sim clock
                tick.script = system.drag_script = DragScript(
                    cfg.run.drag, bus.plant, rate, model=model_for_replay
                )
        return system
    except BaseException:  # a failure or a stop (SIGTERM) at any step: nothing left enabled
        shut_down(group, bus)
        raise


def _silent(text: str) -> None:
    """No progress lines."""


def build_bus(
    cfg: SystemConfig, clock: str, hot: dict[str, np.ndarray] | None = None
) -> tuple[Transport, DriveGroup]:
    """The transport ``bus.transport`` names and its drive group, opened, configured and in
    CSP, not yet enabled (:func:`enable_drives`); ``hot``: the group's fields of the tick's
    hot record (DriveGroup.hot_fields).

    ``sim``: the in-process plant (the run's payload and model error, no scripted world
    torques: the run scripts its own contact). Any other registered transport (``ethercat``,
    ``canopen``) runs on the real clock only; ConfigError for ``clock='sim'`` there.
    """
    if cfg.bus is None:
        raise ConfigError("bus: section missing; hofto-hw run needs the drive data")
    transport = str(cfg.bus.transport)
    if transport == "sim":
        bus: Transport = build_sim_bus(_sim_config(cfg), external=True)
        apply_true_load(bus.plant, cfg)
    else:
        if clock == "sim":
            raise ConfigError(
                f"run.clock: 'sim' needs bus.transport 'sim'; the {transport} bus runs on the "
                "real clock (use --clock real)"
            )
        bus = build_transport(cfg)
    group = build_drive_group(cfg, bus, hot)
    try:
        bus.open()
        group.configure(cfg.bus.drives)
        group.set_mode(Mode.CSP)
    except BaseException:
        bus.close()
        raise
    return bus, group


def check_start_positions(cfg: SystemConfig, bus: Transport, group: DriveGroup, path: Path) -> None:
    """The drives' positions against the last clean shutdown's (one line naming joint,
    stored and read position; the bus is closed when refused)."""
    from hofto_hw.runtime.positions import check_positions, load_positions, turn_bounds

    assert cfg.bus is not None
    try:
        group.cycle()
        bounds = turn_bounds([d.gear_ratio for d in cfg.bus.drives])
        # incremental axes (homing configured) start anywhere: homing sets their zero
        bounds[[d.homing is not None for d in cfg.bus.drives]] = np.inf
        check_positions(load_positions(path), list(cfg.robot.joints), group.q, bounds, path)
    except BaseException:
        bus.close()
        raise


def preload_braked_axes(cfg: SystemConfig, model: RobotModel, group: DriveGroup) -> np.ndarray:
    """Before enabling: the gravity torque of the identified model as the torque offset
    (0x60B2) of every axis with a holding brake (``bus.drives[i].brake``), so the drive holds
    the load the moment the brake opens; returns those axes (int array, maybe empty)."""
    assert cfg.bus is not None
    braked = np.array([i for i, d in enumerate(cfg.bus.drives) if d.brake is not None], int)
    if braked.size:
        group.cycle()
        gravity = model.create_data().gravity(group.q)
        offset = np.zeros(group.n)
        offset[braked] = gravity[braked]
        group.command_position(group.q.copy(), tau_offset=offset)
    return braked


def reenable_refusal(cfg: SystemConfig) -> str:
    """The one line refusing a reset that would power up an arm with master-controlled brakes
    (``brake.control: output``), "" when there is none.

    Such a brake opens by 0x60FE:1 bit 0, which a drive may clear when its power stage goes
    off. Start-up sets it by SDO (:func:`await_brake_release`); the loop's re-enable after a
    reset could only set it from the tick through the process image, and no RxPDO the stack
    builds carries 0x60FE (``drivers.cia402.pdo.RXPDO_MAPPING``), so the loop would enable
    and move the joint against its closed brake: refused, the service's restart opens it."""
    assert cfg.bus is not None
    joints = list(cfg.robot.joints)
    names = [
        joints[i]
        for i, d in enumerate(cfg.bus.drives)
        if d.brake is not None and d.brake.control == "output"
    ]
    if not names:
        return ""
    return (
        f"reset refused: {', '.join(names)}: brake by output needs 0x60FE in the RxPDO for the "
        "loop to re-enable it (restart the service: start-up opens it by SDO)"
    )


def await_brake_release(
    cfg: SystemConfig, bus: Transport, group: DriveGroup, braked: np.ndarray
) -> None:
    """After enabling: open the master-controlled brakes (0x60FE:1 bit 0), hold the position
    for the longest release delay, then refuse (one line naming the joint; the bus is closed)
    a joint that moved more than its ``release_bound`` while its brake opened
    (:class:`drivers.cia402.brake.ReleaseCheck`, which the loop repeats on a re-enable)."""
    from hofto_hw.errors import UserError

    assert cfg.bus is not None
    drives = cfg.bus.drives
    try:
        check = ReleaseCheck.from_drives(list(drives), bus.cycle_time)
        assert check is not None
        check.start(group.q)
        for i in braked:
            if drives[i].brake.control == "output":  # type: ignore[union-attr]
                bus.write_value(int(i), 0x60FE, 1, "u32", 1)
        result = check.RUNNING
        while result == check.RUNNING:
            group.hold()
            bus.wait_next_cycle()
            group.cycle()
            result = check.step(group.q)
        if result >= 0:
            bound = drives[result].brake.release_bound  # type: ignore[union-attr]
            raise UserError(
                f"{list(cfg.robot.joints)[result]}: moved {check.moved * 1e3:+.2f} mrad while "
                f"its brake opened (bound {bound * 1e3:g} mrad): the load is not held (gravity "
                "preload) or the brake drags; motion refused"
            )
    except BaseException:
        bus.close()
        raise


def enable_drives(bus: Transport, group: DriveGroup) -> None:
    """Every drive to Operation enabled (bumpless: the group holds the measured position);
    the bus is closed if that fails."""
    try:
        group.enable()
    except BaseException:
        bus.close()
        raise


def _build_drag(
    cfg: SystemConfig,
    model: RobotModel,
    names: list[str],
    backend: Backend,
    hot: dict[str, np.ndarray] | None = None,
) -> tuple[DragController | None, EnableInput | None, int]:
    """The drag controller of the ``drag:`` section, its enabling input and the row of
    ``tau_ext`` (observer) that drives it; (None, None, 0) without the section."""
    d = cfg.drag
    if d is None:
        if cfg.run.drag is not None:
            raise ConfigError("run.drag: needs a drag: section (the controller's settings)")
        return None, None, 0
    if d.observer not in names:
        raise ConfigError(
            f"drag.observer: {d.observer!r} is not one of the loop's observers {names}"
        )
    ctrl = DragController(d, model, cfg.robot.gravity, backend, hot)
    return ctrl, EnableInput.from_config(d.enable_input), names.index(d.observer)


def _script_contact(system: System) -> ScriptedContact:
    """Add run.collision to the simulated world, timed from now (the loop's t = 0)."""
    c = system.cfg.run.collision
    assert c is not None
    plant = system.bus.plant
    n = system.model.n
    start = plant.t + c.start
    amp = [0.0] * n
    slope = [0.0] * n
    slope[c.joint] = c.peak / c.rise_time
    amp_hold = [0.0] * n
    amp_hold[c.joint] = c.peak
    comps = plant.external.components
    comps.append(
        ExternalTorqueConfig(
            kind="ramp", start=start, duration=c.rise_time, amplitude=amp, slope=slope
        )
    )
    comps.append(
        ExternalTorqueConfig(
            kind="constant", start=start + c.rise_time, duration=c.hold, amplitude=amp_hold
        )
    )
    dt = 1.0 / system.rate_hz
    onset_tick = math.floor(c.start / dt + 1e-9) + 1
    return ScriptedContact(c.joint, c.peak, c.start, onset_tick)
