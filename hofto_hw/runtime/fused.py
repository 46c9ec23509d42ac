"""The tick's common path as one compiled call (numba), calling the parts' own kernels.

:func:`fused_tick` does, for a tick where nothing unusual can happen, what
:meth:`hofto_hw.runtime.tick.Tick.step` does after the exchange, in the same order and through
the same kernels (not copies of them): the drive read (``read_si``), the dynamics snapshot
(``snapshot_native``), the observers (``bank_update``), the tick's flags (``tick_flags``), the
drive scan (``drive_scan``), the limit checks (``limits_quiet``), the collision monitor
(``monitor_tick``), the friction learning (``friction_learn``), the demo path (``path_eval``),
the feed-forward (``inverse_dynamics_native``), the command (``command_raw``) and the record
fill (``fill_tick``). The flight recorder's push stays in Python (the tick's sink).

When a part finds something that is not quiet, the kernel returns the stage where the Python
reference takes over for the rest of the SAME tick (the :data:`STAGES` codes); it has not
written anything the reference redoes from there (every earlier stage is done as the reference
would have done it, every later one untouched).

Arguments: the parts' own arrays, one tuple per part (:meth:`FusedTick.args`, rebuilt from
the parts whenever the tick leaves the fused path, so it always holds the arrays their owners
hold; None for a part the tick does not have), the tick's state (:func:`tick_state_dtype`:
its scalars and arrays as one record), the tick record (a one-element structured array) and
this tick's scalars (loop time, dt, the bus's sample interval, tick number, the loop's
timings). Numba types each array by its dtype, dimensions and layout and keeps it alive
during the call; with numba's JIT switched off (NUMBA_DISABLE_JIT=1) the same source runs
as Python.
"""

from __future__ import annotations

import sys
from typing import TYPE_CHECKING, Any

import numpy as np

from drivers.cia402.kernels import command_raw, read_si
from hofto_hw.control.joint_motion import fade_in
from hofto_hw.control.kernels import friction_learn, path_eval
from hofto_hw.model import kernels as MK
from hofto_hw.model.kernels import inverse_dynamics_native, snapshot_native
from hofto_hw.observers import kernels as K
from hofto_hw.observers.kernels import bank_update
from hofto_hw.recording.kernels import fill_tick
from hofto_hw.runtime.tick_kernels import (
    ESTIMATES_FINITE,
    POWERED,
    command_dt,
    judged,
    jump_gap,
    tick_flags,
)
from safety.collision.kernel import monitor_tick
from safety.kernels import drive_scan, limits_quiet

if TYPE_CHECKING:
    from hofto_hw.runtime.tick import Tick

# the glue the reference computes in Python, compiled from the same functions: one definition
_fade_in = K.jit(fade_in)
_command_dt = K.jit(command_dt)
_jump_gap = K.jit(jump_gap)
_judged = K.jit(judged)

#: stage codes (fused_tick's answer): where the Python reference goes on with this tick
READ = 0  # only the drive read was done: the reference from the snapshot on (section 3)
SAFETY = 1  # sections 1-3b done: the reference from the safety checks on (section 4)
MONITOR = 2  # the monitor ran and flagged: its report, then the reference from there on
CONTROL = 3  # section 4 done, nothing reported: the reference from the controller on (5)
DONE = 4  # everything but the sink's push (and the diagnostics record)
STAGES = ("read", "safety", "monitor", "control", "done")


def tick_state_dtype(n: int, k: int) -> np.dtype:
    """The tick's state that the fused call reads and writes (``Tick.state``, one aligned
    record): the scalars it keeps from tick to tick, its constants, what the fused call found
    and the tick's own arrays (k observer rows, n joints)."""
    f8, i8, b1 = np.float64, np.int64, np.bool_
    return np.dtype(
        [
            ("t_cmd", f8),  # setpoint (path) time [s]
            ("since_fresh", f8),  # [s] since the last fresh sample
            ("sample_dt", f8),  # the interval the observers integrated this tick [s]
            ("monitored", b1),  # the tick record's ``monitored`` (written when it changes)
            # kept by Tick._fuse_refresh: the motion, the enable state, the monitor's settling
            ("kind", i8),  # the motion's update (HOLD_STILL, MOVE_PATH, OTHER)
            ("mode", i8),
            ("t0", f8),  # the path's start [s]
            ("expect", b1),  # the drives are expected enabled
            ("judge_from", i8),  # the first tick the collision monitor judges
            ("was_contact", b1),  # the monitor's contact was on
            # constants: the cycle [s], the stall limit [s], the fade-in's exponent (2.0)
            ("period", f8),
            ("stall", f8),
            ("two", f8),
            # what the fused call found on a tick it did not finish
            ("finite", b1),  # the sample was finite
            ("mflags", i8),  # the monitor's flags
            ("tau_ext", f8, (k, n)),  # the observers' estimates [N·m]
            ("prev", f8, (3, n)),  # last tick's q, qd, tau (a stall's interpolation start)
            ("q_sent", f8, (n,)),  # position target of the last command [rad]
            ("tau_ff", f8, (n,)),  # the feed-forward torque [N·m]
        ],
        align=True,
    )


#: ``kind``: the motion's update this tick (HOLD_STILL: nothing to write; MOVE_PATH: the
#: compiled demo path; OTHER: the reference runs the controller)
HOLD_STILL, MOVE_PATH, OTHER = 0, 1, 2


@K.jit
def fused_tick(
    io: Any,
    snap: Any,
    obs: Any,
    tk: Any,
    lim: np.ndarray,
    coll: Any,
    learn: Any,
    motion: Any,
    path: Any,
    ff: Any,
    rec: np.ndarray,
    t_loop: float,
    dt: float,
    sdt: float,
    tick: int,
    wake: float,
    comp: float,
) -> int:
    """One tick's common path (module docstring) on the parts' arrays (:meth:`FusedTick.args`)
    and the tick record ``rec`` (1,), for loop time ``t_loop`` [s], ``dt`` [s] since the last
    tick, the bus's sample interval ``sdt`` [s] (0: unknown, -1: no sample), tick number
    ``tick`` and the loop's wake-up and compute times [µs]. Returns the stage code where the
    reference goes on."""
    tx, rx, si, states, fault_min, op_enabled = io
    ts = tk[0]
    tau_ext, prev, q_sent, tau_ff = ts["tau_ext"], ts["prev"], ts["q_sent"], ts["tau_ff"]
    # 1-2. the drive read (the exchange is the caller's)
    read_si(tx, si, states)
    sample = si[:3]
    q, qd, tau = si[0], si[1], si[2]
    if sdt < 0.0:
        return READ  # a lost sample: the reference holds the observers
    obs_dt = sdt if sdt > 0.0 else dt
    if not obs_dt <= ts["stall"]:
        return READ  # a stall: the reference integrates the gap in sub-steps
    # 3. snapshot and observers
    sw, so, sh = snap
    finite = snapshot_native(q, qd, tau, sw, so, sh)
    n = q.shape[0]
    terms = (so[:n], so[n + 2], sw[MK.F], so[n], so[n + 3], so[n + 1])
    bank_update(obs, terms, tau_ext, q, qd, tau, finite, obs_dt)
    for i in range(3):
        for j in range(n):
            prev[i, j] = sample[i, j]
    period = ts["period"]
    cmd_dt = _command_dt(dt, period)
    t_cmd = ts["t_cmd"] + cmd_dt
    ts["t_cmd"] = t_cmd
    ts["sample_dt"] = obs_dt
    ts["finite"] = finite
    # 4. safety (good data: the caller checked the status; no fault latched or active)
    expect = ts["expect"]
    if drive_scan(states, fault_min, op_enabled if expect else -1) >= 0:
        return SAFETY
    if not finite:
        return SAFETY
    ms = motion[0]
    mq, mqd, mqdd, q0 = ms["q"], ms["qd"], ms["qdd"], ms["q0"]
    flags = tick_flags(tau_ext, states, POWERED, mqdd, rec[0]["qdd_cmd"])
    if not flags & ESTIMATES_FINITE:
        return SAFETY
    gap = _jump_gap(ts["since_fresh"] + dt, period)
    if limits_quiet(sample, q_sent, lim, 1 + 2 * expect, gap) == 0:
        return SAFETY
    ts["since_fresh"] = 0.0  # good data (what bus.check and Tick._safety do on it)
    monitored = coll is not None and _judged(tick, ts["judge_from"], flags)
    if monitored != ts["monitored"]:
        ts["monitored"] = monitored
        rec[0]["monitored"] = monitored
    ts["mflags"] = 0
    if coll is not None and monitored:
        mdt = obs_dt if obs_dt > 0.0 else dt
        cr, bbuf = coll
        c = cr[0]
        f = monitor_tick(c["fbuf"], bbuf, c["first_tick"], tau_ext, qd, mqdd, mdt, tick)
        ts["mflags"] = f
        if f != 0 or ts["was_contact"]:
            return MONITOR
        if learn is not None:
            lr, row, v_s, l_tau, l_min, every = learn
            lrn = lr[0]
            friction_learn(
                qd, tau_ext[row], mdt, v_s, l_tau, l_min, every, lrn["S"], lrn["b"], lrn["st"]
            )
    # 5. controller (HOLD at rest: nothing; MOVE: the demo path)
    kind = ts["kind"]
    if kind == OTHER:
        return CONTROL
    moved = kind == MOVE_PATH
    if path is not None and moved:
        pk, ramp = path
        t = t_cmd - ts["t0"]
        # the exponent 2 from the state: the compiler cannot turn libm's pow into x·x
        b, bd, bdd = _fade_in(t, ramp, ts["two"])
        path_eval(pk, t, b, bd, bdd, q0, mq, mqd, mqdd)
    # the feed-forward: when the reference moved
    if moved:
        fw, fh = ff
        inverse_dynamics_native(mq, mqd, mqdd, fw, tau_ff, fh)
    # 6. command (CSP with the torque offset)
    command_raw(mq, tau_ff, rx, si, 2)
    # 7. the record (and q_sent = the command just sent)
    fill_tick(
        rec, sample, mq, tau_ext, q_sent, t_loop, tick, ts["mode"], np.int64(0),
        np.int64(0), wake, comp, obs_dt,
    )  # fmt: skip
    return DONE


_SAID: list[str] = []


def say_once(line: str) -> None:
    """Print ``line`` on stderr once per process (why the tick runs without the fused call)."""
    if not _SAID:
        _SAID.append(line)
        print(f"hofto-hw: {line}", file=sys.stderr)


class FusedTick:
    """The fused call's arguments for one :class:`~hofto_hw.runtime.tick.Tick` (built from
    its parts; ``why`` says why not when ``ok`` is False)."""

    def __init__(self, tick: Tick) -> None:
        self.tick = tick
        self.why = self._check(tick)
        self.ok = not self.why
        self.path: Any = None
        if self.ok:
            try:
                self._warm()
            except Exception as exc:  # numba's TypingError/LoweringError, a cache problem
                self.ok = False
                self.why = f"compiling the fused tick failed ({type(exc).__name__})"

    def _check(self, t: Tick) -> str:
        """'' when every part can be fused, else why not."""
        if not K.available():
            return "the fused tick needs numba (" + K.unavailable_reason() + ")"
        g = t.group
        if g._fast is None:
            return "the drive group runs its numpy path"
        snap = t.snapshot
        if snap.model is not t.feedforward.model:
            return "the snapshot and the feed-forward use different models"
        if snap._native is None:
            return "the snapshot does not run the native dynamics"
        bank = self.bank = t._bank
        if not (bank._any and bank._only) or bank._kernel is not bank_update:
            return "an observer is not fused in the bank: " + ", ".join(bank.rest)
        if t._flags is not tick_flags or t._fill is not fill_tick:
            return "the tick's flags and record fill run as Python"
        if not t.bus._use_kernel or not t.limits._use_kernel:
            return "the drive scan or the limit checks run their numpy path"
        c = t.collision
        if c is not None and (not c._use_kernel or c._tool is not None):
            return "the collision monitor runs its numpy path or a tool-force check"
        fr = t.drag.friction if t._learn is not None and t.drag is not None else None
        if fr is not None and not fr._use_kernel:
            return "the friction learning runs its numpy path"
        ff = t.feedforward
        if ff._native is None or ff._id_native is not inverse_dynamics_native:
            return "the feed-forward does not run the native RNEA"
        return ""

    def args(self) -> tuple[Any, ...]:
        """The call's arguments before this tick's scalars: the parts' arrays as they hold
        them now (:attr:`path_ok`: the motion's path is the compiled one)."""
        t = self.tick
        g, snap, m, c, ff = t.group, t.snapshot, t.motion, t.collision, t.feedforward
        coll = None if c is None else (c.state.record, c.state.bbuf)
        learn = None
        if t._learn is not None and t.drag is not None and t.drag.friction is not None:
            fr = t.drag.friction
            learn = (fr.record, t.drag_row, fr.v_s, fr.tau, fr.min_speed, fr.every)
        p = self.path = m.path
        self.path_ok = p is not None and p._use_kernel and p._eval is path_eval
        return (
            (g._tx_bytes, g._rx_bytes, g._si, g.states, t.bus.fault_min, t.bus.op_enabled),
            (snap._W, snap._O, snap._native.handle),  # type: ignore[union-attr]
            t._bank.args,
            t.state,
            t.limits._w,
            coll,
            learn,
            m.state,
            (p._k, float(p.ramp)) if self.path_ok else None,  # type: ignore[union-attr]
            (ff._W, ff._native.handle),  # type: ignore[union-attr]
            t._rec1,
        )

    def _warm(self) -> None:
        """Compile the kernel (all of it) with a lost sample, which returns after the drive
        read, here into scratch rows: no state of the tick is touched."""
        io, *rest = self.args()
        tx, rx, si, states, fault_min, op_enabled = io
        scratch = (tx, rx, si.copy(), states.copy(), fault_min, op_enabled)
        # a lost sample (sdt -1): the read into the scratch rows, then READ; the argument
        # types the tick passes (Tick._fused_step)
        fused_tick(scratch, *rest, 0.0, 0.0, -1.0, 0, 0.0, 0.0)
