"""Admittance for hand guiding, the paper's eq. (34) with K_a = 0, F_d = 0.

Cartesian (:class:`CartesianAdmittance`): per axis of the tool twist V (6,),

    M_a·V' + B_a·V = F_ext_hat      (explicit Euler at the tick: stable for B_a·dt/M_a < 1)

on the unlocked axes, with a force/torque deadband (zero below the band, unity gain above
twice it) and k-fold damping while nobody pushes, then shaped into a joint velocity: the
tool speed limit (translation and rotation, on the state, so it cannot wind up), a
slow-down near singularities (scale w/w0 on the output), damped least squares
qd = Jᵀ·(J·Jᵀ + λ²·I)⁻¹·V, virtual walls of the workspace box and of the soft joint limits,
and the joint velocity limits (a common scale, keeping the direction).

Joint space (:class:`JointAdmittance`): M_a·qdd + B_a·qd = tau_ext_hat per joint, with the
same walls and limits.

Virtual walls: the speed toward a limit is at most (distance to it) / wall_time, so the
command approaches the limit exponentially and never crosses it (dt < wall_time). Units SI:
m, rad, s, N, N·m; twists/wrenches (6,) world-aligned at the tool. Allocation-free per tick.
"""

from __future__ import annotations

import numpy as np

from hofto_hw.config.drag import DragConfig
from hofto_hw.control.wrench import ToolJacobian, norm3
from hofto_hw.model.robot import RobotModel


class JointShaping:
    """Soft joint limits as virtual walls, joint velocity limits, the workspace box and the
    tool speed limit applied to a joint velocity (shared by both admittance variants)."""

    def __init__(self, cfg: DragConfig, model: RobotModel, jac: ToolJacobian) -> None:
        lim = model.limits
        n = model.n
        self.jac = jac
        margin = cfg.soft_limit_margin
        self.lower = np.where(np.isfinite(lim.position_lower), lim.position_lower + margin, -1e9)
        self.upper = np.where(np.isfinite(lim.position_upper), lim.position_upper - margin, 1e9)
        vel = np.where(np.isfinite(lim.velocity), lim.velocity, 3.0)
        self.vmax = vel * cfg.joint_speed_scale
        self.inv_wall = 1.0 / cfg.wall_time
        self.box = cfg.workspace is not None
        self.box_lo = np.array(cfg.workspace.lower if cfg.workspace else (-1e9,) * 3)
        self.box_hi = np.array(cfg.workspace.upper if cfg.workspace else (1e9,) * 3)
        self.v_tool = cfg.command_tool_speed
        self.w_tool = cfg.command_tool_rotation_speed
        self._vmax0, self._v_tool0, self._w_tool0 = self.vmax.copy(), self.v_tool, self.w_tool
        self._hi = np.zeros(n)
        self._lo = np.zeros(n)
        self._ratio = np.zeros(n)
        self._tv = np.zeros(6)
        self.limited = 0  # bit 0 joint wall, 1 joint speed, 2 workspace, 3 tool speed

    def scale_speeds(self, factor: float) -> None:
        """Joint and tool speed limits = the drag section's · ``factor`` (a safety profile's
        ``drag_speed_scale``, <= 1), in place."""
        np.multiply(self._vmax0, factor, out=self.vmax)
        self.v_tool = self._v_tool0 * factor
        self.w_tool = self._w_tool0 * factor

    def workspace(self, twist: np.ndarray) -> None:
        """Cap the linear part of ``twist`` (6,) toward each face of the box (in place)."""
        if not self.box:
            return
        for i in range(3):
            lo, hi = self._box_walls(i)
            v = twist[i]
            if v > hi:
                twist[i] = hi
                self.limited |= 4
            elif v < lo:
                twist[i] = lo
                self.limited |= 4

    def workspace_scale(self, twist: np.ndarray) -> float:
        """The common scale (0-1) of a joint velocity whose tool twist is ``twist`` (6,) that
        keeps the tool inside the box's walls."""
        if not self.box:
            return 1.0
        s = 1.0
        for i in range(3):
            lo, hi = self._box_walls(i)
            v = twist[i]
            if v > hi:
                s = min(s, hi / v)
            elif v < lo:
                s = min(s, lo / v)
        if s < 1.0:
            self.limited |= 4
        return s

    def _box_walls(self, i: int) -> tuple[float, float]:
        """The slowest and fastest tool speed [m/s] along world axis ``i`` the box's walls
        allow at the tool's position: (distance to the wall) / wall_time, toward each face."""
        p = self.jac.position[i]
        hi = max(self.box_hi[i] - p, 0.0) * self.inv_wall
        lo = -max(p - self.box_lo[i], 0.0) * self.inv_wall
        return lo, hi

    def joints(self, q_cmd: np.ndarray, qd: np.ndarray) -> None:
        """Walls of the soft joint limits and the joint speed limits on ``qd`` (n,), in place.

        ``q_cmd`` (n,) [rad]: the position the command integrates from."""
        hi, lo = self._hi, self._lo
        np.subtract(self.upper, q_cmd, out=hi)
        np.maximum(hi, 0.0, out=hi)
        hi *= self.inv_wall
        np.subtract(self.lower, q_cmd, out=lo)
        np.minimum(lo, 0.0, out=lo)
        lo *= self.inv_wall
        if (qd > hi).any() or (qd < lo).any():
            self.limited |= 1
            np.minimum(qd, hi, out=qd)
            np.maximum(qd, lo, out=qd)
        r = self._ratio
        np.abs(qd, out=r)
        r /= self.vmax
        peak = r.max()
        if peak > 1.0:
            qd *= 1.0 / peak  # one scale for all joints keeps the direction
            self.limited |= 2

    def tool_speed(self, qd: np.ndarray, arm_speed: float = 0.0) -> None:
        """Scale ``qd`` so the tool moves at most at the tool speed limits (in place);
        ``arm_speed`` [m/s]: the measured tool speed (:func:`lead_capped_speed`)."""
        tv = self._tv
        np.matmul(self.jac.J, qd, out=tv)
        v = norm3(tv, 0)
        w = norm3(tv, 3)
        v_tool = lead_capped_speed(self.v_tool, v, arm_speed)
        s = min(1.0, v_tool / v if v > 0.0 else 1.0, self.w_tool / w if w > 0.0 else 1.0)
        if s < 1.0:
            qd *= s
            self.limited |= 8


class CartesianAdmittance:
    """Cartesian admittance (see module docstring). State ``twist`` (6,); after
    :meth:`update`: ``qd`` (n,) [rad/s], ``scale`` (singularity slow-down, 0-1)."""

    def __init__(self, cfg: DragConfig, model: RobotModel, jac: ToolJacobian) -> None:
        self.jac = jac
        self.shaping = JointShaping(cfg, model, jac)
        u = cfg.unlock
        self.mask = np.array([u.x, u.y, u.z, u.rotation, u.rotation, u.rotation], dtype=float)
        self.inv_mass = 1.0 / np.array([cfg.mass] * 3 + [cfg.rotational_mass] * 3)
        self.damping = np.array([cfg.damping] * 3 + [cfg.rotational_damping] * 3)
        self.release = cfg.release_damping
        self.f_dead = cfg.force_deadband
        self.m_dead = cfg.torque_deadband
        self.v_max = cfg.command_tool_speed
        self.w_max = cfg.command_tool_rotation_speed
        self.a_max = cfg.max_tool_acceleration
        self.alpha_max = cfg.max_tool_angular_acceleration
        self.w0 = cfg.singular_manipulability
        self.min_scale = cfg.singular_min_scale
        self._gains0 = (self.inv_mass.copy(), self.damping.copy(), self.v_max, self.w_max)
        self.twist = np.zeros(6)
        self.qd = np.zeros(model.n)
        self.scale = 1.0
        self._f = np.zeros(6)
        self._a = np.zeros(6)
        self._out = np.zeros(6)

    def reset(self) -> None:
        """At rest."""
        self.twist.fill(0.0)
        self.qd.fill(0.0)

    def apply_profile(self, mass: float, damping: float, speed: float) -> None:
        """M_a, B_a and the speed limits = the drag section's · the factors (a safety
        profile's), in place; at rest only (the caller's rule)."""
        inv_mass, damp, v_max, w_max = self._gains0
        np.multiply(inv_mass, 1.0 / mass, out=self.inv_mass)
        np.multiply(damp, damping, out=self.damping)
        self.v_max, self.w_max = v_max * speed, w_max * speed
        self.shaping.scale_speeds(speed)

    def update(
        self, wrench: np.ndarray, q_cmd: np.ndarray, dt: float, arm_speed: float = 0.0
    ) -> np.ndarray:
        """Advance by ``dt`` [s] with the tool wrench (6,) [N, N·m]; ``jac`` must be updated
        at ``q_cmd``. ``arm_speed`` [m/s]: the measured tool speed (see
        :func:`lead_capped_speed`; 0 = no lead). Returns the joint velocity command (n,) (a
        view of ``qd``)."""
        f, a, v = self._f, self._a, self.twist
        np.multiply(wrench, self.mask, out=f)
        pushed = _deadband(f, 0, self.f_dead)
        pushed |= _deadband(f, 3, self.m_dead)
        # M·v' = F - B·v, explicit Euler; more damping when nobody pushes (the arm stops)
        np.multiply(self.damping, v, out=a)
        if not pushed:
            a *= self.release
        np.subtract(f, a, out=a)
        a *= self.inv_mass
        a *= dt
        _limit_norm(a, 0, self.a_max * dt)
        _limit_norm(a, 3, self.alpha_max * dt)
        v += a
        v *= self.mask
        _limit_norm(v, 0, lead_capped_speed(self.v_max, norm3(v, 0), arm_speed))
        _limit_norm(v, 3, self.w_max)
        sh = self.shaping
        sh.limited = 0
        w = self.jac.w
        self.scale = 1.0 if w >= self.w0 else max(self.min_scale, w / self.w0)
        out = self._out
        np.multiply(v, self.scale, out=out)
        sh.workspace(out)
        self.jac.joint_velocity(out, self.qd)
        sh.joints(q_cmd, self.qd)
        return self.qd


class JointAdmittance:
    """Joint-space admittance M_a·qdd + B_a·qd = tau_ext_hat (deadband per joint), with the
    walls, joint and tool speed limits and the workspace box. ``qd`` (n,) is the state."""

    def __init__(self, cfg: DragConfig, model: RobotModel, jac: ToolJacobian) -> None:
        n = model.n
        m, b = cfg.joint_gains(n)
        self.jac = jac
        self.shaping = JointShaping(cfg, model, jac)
        self.inv_mass = 1.0 / np.asarray(m, dtype=float)
        self.damping = np.asarray(b, dtype=float)
        self.dead = cfg.joint_deadband
        self.release = cfg.release_damping
        self._gains0 = (self.inv_mass.copy(), self.damping.copy())
        self.qd = np.zeros(n)
        self.scale = 1.0
        self._t = np.zeros(n)
        self._a = np.zeros(n)
        self._tw = np.zeros(6)

    def reset(self) -> None:
        """At rest."""
        self.qd.fill(0.0)

    def apply_profile(self, mass: float, damping: float, speed: float) -> None:
        """M_a, B_a and the speed limits = the drag section's · the factors, in place."""
        inv_mass, damp = self._gains0
        np.multiply(inv_mass, 1.0 / mass, out=self.inv_mass)
        np.multiply(damp, damping, out=self.damping)
        self.shaping.scale_speeds(speed)

    def update(
        self, tau_ext: np.ndarray, q_cmd: np.ndarray, dt: float, arm_speed: float = 0.0
    ) -> np.ndarray:
        """Advance by ``dt`` [s] with tau_ext_hat (n,) [N·m]; ``arm_speed`` [m/s] the
        measured tool speed (see :func:`lead_capped_speed`); returns qd (n,) [rad/s]."""
        t, a, qd = self._t, self._a, self.qd
        # deadband per joint (the gain of _band_gain, per joint)
        band = self.dead
        pushed = False
        for i in range(qd.shape[0]):
            x = tau_ext[i]
            g = _band_gain(x if x >= 0.0 else -x, band)
            t[i] = x * g
            pushed |= g > 0.0
        np.multiply(self.damping, qd, out=a)
        if not pushed:
            a *= self.release
        np.subtract(t, a, out=a)
        a *= self.inv_mass
        a *= dt
        qd += a
        sh = self.shaping
        sh.limited = 0
        sh.tool_speed(qd, arm_speed)
        if sh.box:
            np.matmul(self.jac.J, qd, out=self._tw)
            qd *= sh.workspace_scale(self._tw)
        sh.joints(q_cmd, qd)
        return qd


def lead_capped_speed(limit: float, command: float, arm: float) -> float:
    """The command's tool speed limit [m/s] with the arm's lead over the command taken off:
    ``limit`` the command's own limit, ``command`` its speed before the cap, ``arm`` the
    measured tool speed (of the last sample).

    The drives' position loop drives the arm at the command's speed plus its gain times the
    following error: after a hand lets go of a hard push, the estimate's lag keeps the hand
    feed-forward pulling the arm back while the command runs at the limit, and the loop then
    takes up that error above the command (ER3A sim, 80 N release, paper gains: 263 mm/s
    true against a 225 mm/s command). Capping the command at limit - (arm - command) keeps
    the arm's own speed at the limit whatever the observer's lag; never below 0."""
    lead = arm - command
    if lead <= 0.0:
        return limit
    return max(limit - lead, 0.0)


def _band_gain(norm: float, band: float) -> float:
    """Gain of the deadband at magnitude ``norm``: 0 below ``band``, rising linearly to 1 at
    2·band (magnitude 2·(norm - band)), 1 above: continuous (no click at the band edge) and
    exact for real pushes (no F/B_a bias above 2·band, unlike a shrinking deadband)."""
    if norm <= band:
        return 0.0
    if norm >= 2.0 * band:
        return 1.0
    return 2.0 * (norm - band) / norm


def _deadband(x: np.ndarray, i: int, band: float) -> bool:
    """Deadband on the norm of x[i:i+3] (see :func:`_band_gain`), keeping the direction;
    True when something is left."""
    s = _band_gain(norm3(x, i), band)
    x[i] *= s
    x[i + 1] *= s
    x[i + 2] *= s
    return s > 0.0


def _limit_norm(x: np.ndarray, i: int, limit: float) -> None:
    """Scale x[i:i+3] down to norm ``limit`` if above it."""
    norm = norm3(x, i)
    if norm > limit:
        s = limit / norm
        x[i] *= s
        x[i + 1] *= s
        x[i + 2] *= s
