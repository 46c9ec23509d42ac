"""Closed-loop drag on the simulated arm, in simulated time: the harness of issue 9's tests
and of tools/bench_drag.py, until the runtime loop calls the DragController itself.

One tick, as the loop will run it: SimBus exchange (emulated CiA-402 drives in CSP step the
plant) -> measured q, qd, motor torque -> one observer (HOFTO or momentum) -> DragController
-> stop handling (what the service's stop controller does: a category 2 request, a force
limit or an off-tool contact ramps the reference to standstill at the acceleration limits and
holds) -> CSP target + inverse-dynamics torque offset on the nominal model.

The simulated world (:class:`HandForces`) applies scripted forces to the *true* arm: a push at
the tool, a push on a link, or a "virtual hand" pulling the tool through a spring-damper.
Figures (:func:`drag_figures`, :func:`path_error_mm`) are computed from the true plant state,
which the controller never sees. Offline: allocates freely.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pinocchio as pin

from drivers.cia402.drive_group import DriveGroup
from drivers.cia402.state_machine import Mode
from drivers.sim.plant import Plant
from drivers.sim.simbus import SimBus
from hofto_hw.config.drag import DragConfig
from hofto_hw.config.loader import load_config
from hofto_hw.config.locate import PROJECT_CONFIGS
from hofto_hw.config.models import SystemConfig
from hofto_hw.control.drag import DragController
from hofto_hw.control.taught_path import TaughtPathRecorder
from hofto_hw.model.payload import apply_payload, payload_from_config
from hofto_hw.model.robot import RobotModel
from hofto_hw.observers import make_observer

ER3A = PROJECT_CONFIGS / "er3a.yaml"
#: where the README main job's arm stands after its collision stop (measured, sim clock,
#: configs/er3a.yaml): the pose its scripted 20 N drag starts from [rad]
MAIN_JOB_POSE = [-0.79995, -0.06658, 0.98506, 0.97171, 1.04007, 0.72998]
#: contact-free motion before that drag: the main job's path (run.path) at 0.6 of its
#: amplitude about that pose, (amplitude [rad], period [s]) for :meth:`DragSim.free_motion`
MAIN_JOB_PATH = ([0.48, 0.3, 0.36, 0.6, 0.48, 0.72], [4.0, 3.5, 3.0, 2.5, 2.8, 2.2])
#: harness stop modes
RUN, STOPPING = 0, 1


# ------------------------------------------------------------------------ the world


@dataclass
class ToolPush:
    """A force ``force`` (3,) [N] at the tool from ``start`` to ``end`` [s], with linear
    ramps of ``ramp`` [s] inside that window."""

    force: tuple[float, float, float]
    start: float
    end: float
    ramp: float = 0.02

    def profile(self, t: float) -> float:
        if t <= self.start or t >= self.end:
            return 0.0
        return min(1.0, (t - self.start) / self.ramp, (self.end - t) / self.ramp)


@dataclass
class LinkPush(ToolPush):
    """A force at the middle of link ``link`` (between joint ``link`` and the next)."""

    link: int = 3


@dataclass
class VirtualHand:
    """A hand moving from the tool's start along ``direction`` for ``length`` [m] at
    ``speed`` [m/s] from ``start`` [s], pulling the tool with a spring ``stiffness`` [N/m]
    and damper ``damping`` [N·s/m]. ``force`` (3,) is the last force applied [N]."""

    direction: tuple[float, float, float] = (1.0, 0.0, 0.0)
    length: float = 0.3
    speed: float = 0.15
    start: float = 0.5
    stiffness: float = 500.0
    damping: float = 40.0
    origin: np.ndarray | None = None
    force: np.ndarray = field(default_factory=lambda: np.zeros(3))

    def hand(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Hand position [m] and velocity [m/s] at ``t``."""
        assert self.origin is not None
        u = np.asarray(self.direction, dtype=float)
        u = u / np.linalg.norm(u)
        s = min(max(t - self.start, 0.0) * self.speed, self.length)
        moving = self.start < t < self.start + self.length / self.speed
        return self.origin + s * u, (self.speed * u if moving else np.zeros(3))


class HandForces:
    """External joint torques of the scripted world (the plant's ``external``)."""

    def __init__(self, model: RobotModel) -> None:
        self.model = model
        self.pm = model.pin_model
        self.data = self.pm.createData()
        self.tool = model.tool_frame_id
        self.pushes: list[ToolPush] = []
        self.hand: VirtualHand | None = None
        self.n = model.n

    def joint_space_only(self) -> bool:
        return False

    def evaluate(
        self, t: float, q: np.ndarray, qd: np.ndarray, out: np.ndarray | None = None
    ) -> np.ndarray:
        tau = np.zeros(self.n) if out is None else out
        tau.fill(0.0)
        if not self.pushes and self.hand is None:
            return tau
        pm, d = self.pm, self.data
        pin.computeJointJacobians(pm, d, q)
        pin.updateFramePlacements(pm, d)
        Jt = pin.getFrameJacobian(pm, d, self.tool, pin.LOCAL_WORLD_ALIGNED)[:3]
        for p in self.pushes:
            s = p.profile(t)
            if s == 0.0:
                continue
            f = s * np.asarray(p.force, dtype=float)
            if isinstance(p, LinkPush):
                J = pin.getJointJacobian(pm, d, p.link, pin.LOCAL_WORLD_ALIGNED)
                o = d.oMi[p.link].translation
                r = 0.5 * (d.oMi[p.link + 1].translation - o)
                Jp = J[:3] - _skew(r) @ J[3:]
                tau += Jp.T @ f
            else:
                tau += Jt.T @ f
        if self.hand is not None:
            h = self.hand
            x = d.oMf[self.tool].translation
            v = Jt @ qd
            if h.origin is None:
                h.origin = x.copy()
            hp, hv = h.hand(t)
            h.force = h.stiffness * (hp - x) + h.damping * (hv - v)
            tau += Jt.T @ h.force
        return tau


def _skew(r: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -r[2], r[1]], [r[2], 0.0, -r[0]], [-r[1], r[0], 0.0]])


# ------------------------------------------------------------------------ the harness


@dataclass
class DragRun:
    """Per-tick record of a run: t (N,); true q, qd, reference q_ref (N, n); wrench (N, 6);
    reason, mode, limited (N,); pressed (N,) bool; hand force (N, 3) if a virtual hand."""

    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    q_ref: np.ndarray
    wrench: np.ndarray
    reason: np.ndarray
    mode: np.ndarray
    limited: np.ndarray
    pressed: np.ndarray
    hand_force: np.ndarray
    contact_link: int = 0
    stop_tick: int = -1
    tool: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    tool_v: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))


class DragSim:
    """The simulated arm (SimBus + DriveGroup in CSP) + one observer + a DragController.

    ``model_error``: relative error of the true arm; ``noise``: keep the config's sensor
    noise (torque, velocity, quantisation) or remove it. ``drag``: overrides of the ``drag:``
    section (a dict of DragConfig fields). ``q0``: start pose (default: robot.home).
    ``gains``: ``loop`` runs the observer as the service's loop does (``loop.observers``
    over the top-level ``observers``: the estimate the drag really gets), ``paper`` the
    top-level ``observers`` (the paper's Section IV gains). ``payload``: the arm holds
    ``safety.payload`` and the model knows it, as in ``hofto-hw run`` (the README main job).
    """

    def __init__(
        self,
        config: Path | str = ER3A,
        *,
        observer: str = "hofto",
        model_error: float = 0.1,
        noise: bool = True,
        seed: int = 7,
        drag: dict | None = None,
        q0: np.ndarray | list[float] | None = None,
        gains: str = "loop",
        payload: bool = False,
    ) -> None:
        cfg = load_config(Path(config))
        base = cfg.drag.model_dump() if cfg.drag is not None else {}
        base.update(drag or {})
        base["observer"] = observer
        drag_cfg = DragConfig.model_validate(base)
        cfg = SystemConfig.model_validate({**cfg.model_dump(), "drag": drag_cfg.model_dump()})
        self.cfg = cfg
        self.drag_cfg = drag_cfg
        assert cfg.simulation is not None and cfg.bus is not None
        # 2 plant substeps per 1 ms tick (the config's 4 halves the harness speed for no
        # visible difference in these slow motions)
        sim_update: dict = {
            "external": [],
            "model_error": model_error,
            "seed": seed,
            "substeps": 2,
        }
        if not noise:
            sim_update.update(torque_noise=0.0, velocity_noise=0.0, encoder_counts_per_rev=None)
        sim = cfg.simulation.model_copy(update=sim_update)
        self.dt = cfg.cycle_time
        self.model = RobotModel.from_config(cfg.robot)
        plant = Plant(self.model, sim, self.dt)
        if payload and cfg.safety.payload.mass > 0.0:
            load = payload_from_config(cfg.safety.payload)
            apply_payload(self.model, load)
            apply_payload(plant.true_model, load)
        if q0 is not None:
            plant.reset(np.asarray(q0, dtype=float))
        self.world = HandForces(plant.true_model)
        plant.external = self.world  # type: ignore[assignment]
        self.plant = plant
        self.bus = SimBus.from_config(cfg.bus, plant, axis_names=list(cfg.robot.joints))
        self.group = DriveGroup.from_config(self.bus, cfg.bus)
        self.bus.open()
        self.group.configure(cfg.bus.drives)
        self.group.set_mode(Mode.CSP)
        self.group.enable()
        if gains not in ("loop", "paper"):
            raise ValueError(f"gains: {gains!r} is not 'loop' or 'paper'")
        table = dict(cfg.observers)
        if gains == "loop":
            table.update(cfg.loop.observers or {})
        self.gains = gains
        self.observer = make_observer(table[observer], self.model.copy())
        self.drag = DragController(drag_cfg, self.model, cfg.robot.gravity)
        self.ff = self.model.create_data()
        n = self.model.n
        acc = self.model.limits.acceleration
        self.accel = np.where(np.isfinite(acc), acc, 10.0)
        self.q_ref = np.zeros(n)
        self.qd_ref = np.zeros(n)
        self.qdd_ref = np.zeros(n)
        self.tau_ff = np.zeros(n)
        self.stop_mode = RUN
        self.t = 0.0
        g = self.group
        g.cycle()
        self.observer.reset(g.q, g.qd)
        self.drag.start(g.q)
        np.copyto(self.q_ref, g.q)
        self.t0 = plant.t

    # ------------------------------------------------------------------ ticking

    def _ramp_down(self, dt: float) -> None:
        """The category 2 stop the service's stop controller acts: decelerate the reference
        at the acceleration limits to standstill, then hold."""
        step = np.minimum(self.accel * dt, np.abs(self.qd_ref)) * np.sign(self.qd_ref)
        self.qd_ref -= step
        self.qdd_ref[:] = -step / dt
        self.q_ref += self.qd_ref * dt

    def run(
        self,
        duration: float,
        pressed: Callable[[float], bool] | bool = True,
        on_tick: Callable[[DragSim], None] | None = None,
        trajectory: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
        recorder: TaughtPathRecorder | None = None,
    ) -> DragRun:
        """Run ``duration`` [s] of simulated time. ``pressed(t)``: the enabling input at run
        time t. ``trajectory`` (q, qd, qdd) (K, n): follow it instead of dragging (replay).
        ``recorder``: records the measured q of every tick while the drag is active."""
        dt = self.dt
        n = self.model.n
        N = round(duration / dt)
        rec = DragRun(
            t=np.zeros(N),
            q=np.zeros((N, n)),
            qd=np.zeros((N, n)),
            q_ref=np.zeros((N, n)),
            wrench=np.zeros((N, 6)),
            reason=np.zeros(N, dtype=np.int32),
            mode=np.zeros(N, dtype=np.int32),
            limited=np.zeros(N, dtype=np.int32),
            pressed=np.zeros(N, dtype=bool),
            hand_force=np.zeros((N, 3)),
        )
        press = pressed if callable(pressed) else (lambda _t, v=bool(pressed): v)
        g, obs, drag, plant = self.group, self.observer, self.drag, self.plant
        for k in range(N):
            t = self.t
            g.cycle()
            tau_ext = obs.update(g.q, g.qd, g.tau, dt)
            p = bool(press(t))
            latched = self.stop_mode == STOPPING
            if trajectory is not None:
                i = min(k, trajectory[0].shape[0] - 1)
                self.q_ref[:] = trajectory[0][i]
                self.qd_ref[:] = trajectory[1][i]
                self.qdd_ref[:] = trajectory[2][i]
                # contact-free motion: the drag learns the friction model's error, as the
                # loop's tick does outside drag mode
                drag.learn(g.qd, tau_ext, dt)
            else:
                reason = drag.update(g.q, g.qd, tau_ext, dt, p, latched)
                if self.stop_mode == RUN and (reason != 0 or drag.category == 2):
                    self.stop_mode = STOPPING
                    rec.stop_tick = k
                    if drag.contact_link:
                        rec.contact_link = drag.contact_link
                if self.stop_mode == STOPPING:
                    self._ramp_down(dt)
                else:
                    np.copyto(self.q_ref, drag.q_cmd)
                    np.copyto(self.qd_ref, drag.qd_cmd)
                    np.copyto(self.qdd_ref, drag.qdd_cmd)
                rec.reason[k] = reason
                rec.limited[k] = drag.limited
                rec.wrench[k] = drag.wrench
                rec.mode[k] = drag.enabling.state
                if recorder is not None and drag.active:
                    recorder.push(t, g.q)
            self.ff.inverse_dynamics(self.q_ref, self.qd_ref, self.qdd_ref, out=self.tau_ff)
            if trajectory is None and self.stop_mode == RUN:
                self.tau_ff += drag.tau_offset  # the hand's torque off the drives' offset
            g.command_position(self.q_ref, self.tau_ff)
            if on_tick is not None:
                on_tick(self)
            rec.t[k] = t
            rec.q[k] = plant.q
            rec.qd[k] = plant.qd
            rec.q_ref[k] = self.q_ref
            rec.pressed[k] = p
            if self.world.hand is not None:
                rec.hand_force[k] = self.world.hand.force
            self.t += dt
        rec.tool, rec.tool_v = tool_motion(self.plant.true_model, rec.q, rec.qd)
        return rec

    def free_motion(
        self,
        amplitude: np.ndarray | list[float],
        period: np.ndarray | list[float],
        duration: float = 3.0,
        settle: float = 0.3,
    ) -> DragRun:
        """Contact-free motion before a drag, as the README main job's path: per joint
        q0 + A·sin(2π·t/P)·sin²(π·t/T) for ``duration`` T [s] (starts and ends at the
        present pose, at rest), then ``settle`` [s] of holding; the drag learns the friction
        model's error meanwhile (as the loop does outside drag mode). Afterwards the drag
        waits for a new press (:meth:`clear_stop`)."""
        dt = self.dt
        t = np.arange(round(duration / dt)) * dt
        q0 = self.group.q.copy()
        a = np.asarray(amplitude, dtype=float)
        w = 2.0 * np.pi / np.asarray(period, dtype=float)
        env = np.sin(np.pi * t / duration) ** 2
        q = q0 + env[:, None] * a * np.sin(w * t[:, None])
        qd = np.gradient(q, dt, axis=0)
        qdd = np.gradient(qd, dt, axis=0)
        n_hold = max(1, round(settle / dt))
        q = np.vstack([q, np.repeat(q0[None], n_hold, axis=0)])
        qd = np.vstack([qd, np.zeros((n_hold, q0.size))])
        qdd = np.vstack([qdd, np.zeros((n_hold, q0.size))])
        run = self.run(q.shape[0] * dt, trajectory=(q, qd, qdd))
        self.clear_stop()
        return run

    def clear_stop(self) -> None:
        """What an explicit reset does: run again (the drag waits for a new press)."""
        self.stop_mode = RUN
        self.drag.start(self.group.q)
        np.copyto(self.q_ref, self.group.q)
        self.qd_ref.fill(0.0)
        self.qdd_ref.fill(0.0)


def tool_motion(model: RobotModel, q: np.ndarray, qd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Tool position [m] and linear velocity [m/s], (N, 3) each, of joint samples (N, n)."""
    pm = model.pin_model
    d = pm.createData()
    fid = model.tool_frame_id
    p = np.zeros((q.shape[0], 3))
    v = np.zeros((q.shape[0], 3))
    for k in range(q.shape[0]):
        J = pin.computeFrameJacobian(pm, d, q[k], fid, pin.LOCAL_WORLD_ALIGNED)
        p[k] = d.oMf[fid].translation
        v[k] = J[:3] @ qd[k]
    return p, v


# ------------------------------------------------------------------------ figures


def drag_figures(
    run: DragRun,
    push: ToolPush,
    damping: float,
    standstill: float = 0.01,
    rest_fraction: float = 0.05,
    settle: float = 0.5,
) -> dict[str, float]:
    """Issue 9's drag figures of a run with one constant tool push (SI; times in ms).

    - steady_speed_mps: mean tool speed along the push over [start + settle, end - 0.05];
    - expected_speed_mps: |F| / B_a;
    - off_axis_mps: norm of the mean tool velocity across the push over the same window;
    - rest_time_ms: the release instant is the push's end (the hand's force is zero);
      the arm is at rest when the tool is slower than ``rest_fraction`` of the steady
      speed (at least 1 mm/s) *and* every joint slower than ``standstill`` [rad/s]
      (drag.standstill_speed, the service's standstill): the time from the release to the
      last tick either is not yet true (the later of the two below);
    - rest_time_tool_ms, rest_time_joints_ms: each criterion alone;
    - rest_time_command_ms: the same as the joints' for the reference the controller
      commands (the rest of the arm's time is the drives' position loop taking up its
      following error);
    - max_speed_mps: the highest tool speed of the run.
    """
    f = np.asarray(push.force, dtype=float)
    u = f / np.linalg.norm(f)
    w = (run.t >= push.start + settle) & (run.t <= push.end - 0.05)
    v = run.tool_v[w]
    along = v @ u
    across = v - np.outer(along, u)
    expected = float(np.linalg.norm(f) / damping)
    speed = np.linalg.norm(run.tool_v, axis=1)
    joint_speed = np.abs(run.qd).max(axis=1)
    after = np.flatnonzero(run.t >= push.end)
    dt = float(run.t[1] - run.t[0])
    ref_speed = np.zeros_like(joint_speed)
    ref_speed[1:] = np.abs(np.diff(run.q_ref, axis=0)).max(axis=1) / dt

    def _rest(moving: np.ndarray) -> float:
        return 0.0 if moving.size == 0 else float(run.t[moving[-1]] - push.end + dt)

    steady = float(along.mean())
    tool_rest = max(rest_fraction * steady, 1e-3)
    joints = 1e3 * _rest(after[joint_speed[after] > standstill])
    tool = 1e3 * _rest(after[speed[after] > tool_rest])
    return {
        "steady_speed_mps": steady,
        "expected_speed_mps": expected,
        "off_axis_mps": float(np.linalg.norm(across.mean(axis=0))),
        "rest_time_ms": max(joints, tool),
        "rest_time_joints_ms": joints,
        "rest_time_tool_ms": tool,
        "rest_time_command_ms": 1e3 * _rest(after[ref_speed[after] > standstill]),
        "max_speed_mps": float(speed.max()),
    }


def drift_mps(run: DragRun, start: float = 0.0) -> dict[str, float]:
    """Tool drift with no push from ``start`` [s]: net displacement / time and the peak of
    the 1 s moving-average speed [m/s]."""
    w = run.t >= start
    p, t = run.tool[w], run.t[w]
    net = float(np.linalg.norm(p[-1] - p[0]) / (t[-1] - t[0]))
    dt = t[1] - t[0]
    m = max(1, round(1.0 / dt))
    if p.shape[0] > m:
        moved = np.linalg.norm(p[m:] - p[:-m], axis=1) / (m * dt)
        peak = float(moved.max())
    else:
        peak = net
    return {"drift_mps": net, "drift_peak_mps": peak}


def path_error_mm(taught_tool: np.ndarray, replayed_tool: np.ndarray) -> float:
    """Largest distance [mm] from a replayed tool position to the taught tool path (dense
    samples, nearest point)."""
    from scipy.spatial import cKDTree

    d, _ = cKDTree(taught_tool).query(replayed_tool)
    return float(1e3 * d.max())
