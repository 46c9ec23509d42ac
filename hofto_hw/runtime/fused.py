"""The tick after the exchange as one compiled call (numba), calling the parts' own kernels.

:func:`fused_tick` runs on every tick, the only place sections 1-3 run: the drive read
(``read_si``) and the dynamics snapshot and observers (``snapshot_native``,
``bank_update``) over the sample interval, a lost sample held and a stall integrated in
one-cycle sub-steps. On a tick where nothing unusual can happen (the caller's ``quiet``) it
goes on, in the order of :meth:`hofto_hw.runtime.tick.Tick.step` and through the same
kernels (not copies of them): the tick's flags (``tick_flags``), the drive scan
(``drive_scan``), the limit checks (``limits_quiet``), the collision monitor
(``monitor_tick``), the friction learning (``friction_learn``), the demo path (``path_eval``),
the feed-forward (``inverse_dynamics_native``), the command (``command_raw``) and the record
fill (``fill_tick``). The flight recorder's push stays in Python (the tick's sink).

When a part finds something that is not quiet, the kernel returns the stage where the tick's
Python stages take over for the rest of the SAME tick (the :data:`STAGES` codes); it has not
written anything they redo from there (every earlier stage is done as they would have done
it, every later one untouched). tests/support/reference_tick.py runs those stages on every
tick, sections 1-3 through the parts' own methods: the reference the tests compare with.

Arguments: few, so that numba's dispatch unboxes little on every call (each array argument
costs ~0.1-0.3 µs, more with the caches cold after the exchange): the tick's one hot record
(:func:`hot_dtype`: the tick's state and the parts' hot arrays as its fields, the parts'
arrays being views into it, :func:`relocate`), the observer bank's tuple (its observers'
own records), the process images' bytes, the tick record (a one-element structured array)
and this tick's scalars (loop time, dt, the bus's sample interval, tick number, the loop's
timings). Numba types each field by its dtype and shape; with numba's JIT switched off
(NUMBA_DISABLE_JIT=1) the same source runs as Python.
"""

from __future__ import annotations

import sys
from functools import partial
from typing import TYPE_CHECKING, Any

import numpy as np

from drivers.cia402.kernels import command_raw, read_si
from hofto_hw.control.joint_motion import fade_in
from hofto_hw.control.kernels import friction_learn, path_eval
from hofto_hw.model import kernels as MK
from hofto_hw.model.kernels import inverse_dynamics_native, snapshot_native
from hofto_hw.observers import kernels as K
from hofto_hw.observers.bank import ObserverBank
from hofto_hw.observers.kernels import bank_update
from hofto_hw.recording.kernels import fill_tick
from hofto_hw.runtime.tick_kernels import (
    ESTIMATES_FINITE,
    POWERED,
    command_dt,
    gap_steps,
    judged,
    jump_gap,
    lerp,
    tick_flags,
)
from safety.collision.kernel import monitor_tick
from safety.kernels import drive_scan, limits_quiet

if TYPE_CHECKING:
    from hofto_hw.runtime.tick import Tick

# the glue the Python stages compute, compiled from the same functions: one definition
_fade_in = K.jit(fade_in)
_command_dt = K.jit(command_dt)
_jump_gap = K.jit(jump_gap)
_judged = K.jit(judged)
_gap_steps = K.jit(gap_steps)
_lerp = K.jit(lerp)

#: stage codes (fused_tick's answer): where the tick's Python stages go on with this tick
SAFETY = 1  # sections 1-3 done: the stages from the drag and the safety checks on (3b, 4)
MONITOR = 2  # the monitor ran and flagged: its report, then the stages from there on
CONTROL = 3  # section 4 done, nothing reported: the stages from the controller on (5)
DONE = 4  # everything but the sink's push (and the diagnostics record)
STAGES = {SAFETY: "safety", MONITOR: "monitor", CONTROL: "control", DONE: "done"}


def tick_state_dtype(n: int, k: int) -> np.dtype:
    """The tick's state that the fused call reads and writes (``Tick.state``, one aligned
    record): the scalars it keeps from tick to tick, its constants, what the fused call found
    and the tick's own arrays (k observer rows, n joints)."""
    f8, i8, b1 = np.float64, np.int64, np.bool_
    return np.dtype(
        [
            ("t_cmd", f8),  # setpoint (path) time [s]
            ("cmd_dt", f8),  # this tick's setpoint step [s] (tick_kernels.command_dt)
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
            # the parts' constants, copied at each refresh (FusedTick.args): the drive codes,
            # the native models' handles, the demo path's ramp [s], the friction learning's
            # row, speed [rad/s], time constant [s], minimum speed [rad/s] and decimation
            ("fault_min", i8),
            ("op_enabled", i8),
            ("snap_h", i8),
            ("ff_h", i8),
            ("ramp", f8),
            ("has_coll", b1),
            ("has_learn", b1),
            ("l_row", i8),
            ("l_vs", f8),
            ("l_tau", f8),
            ("l_min", f8),
            ("l_every", i8),
            # what the fused call found on a tick it did not finish
            ("finite", b1),  # the sample was finite
            ("mflags", i8),  # the monitor's flags
            ("tau_ext", f8, (k, n)),  # the observers' estimates [N·m]
            ("prev", f8, (3, n)),  # last tick's q, qd, tau (a stall's interpolation start)
            ("interp", f8, (3, n)),  # one stall sub-step's q, qd, tau
            ("q_sent", f8, (n,)),  # position target of the last command [rad]
            ("tau_ff", f8, (n,)),  # the feed-forward torque [N·m]
        ],
        align=True,
    )


#: ``kind``: the motion's update this tick (HOLD_STILL: nothing to write; MOVE_PATH: the
#: compiled demo path; OTHER: the Python stages run the controller)
HOLD_STILL, MOVE_PATH, OTHER = 0, 1, 2


@K.jit
def _observe(
    obs: Any, sw: np.ndarray, so: np.ndarray, h: int, tau_ext: np.ndarray, x: np.ndarray, dt: float
) -> bool:
    """The dynamics snapshot of the sample ``x`` (3, n: q, qd, tau) in the snapshot's
    workspace ``sw``/``so`` (native model ``h``), then every observer of the bank's tuple
    ``obs`` by ``dt`` [s], each estimate into its row of ``tau_ext``. Returns ``finite``."""
    q, qd, tau = x[0], x[1], x[2]
    finite = snapshot_native(q, qd, tau, sw, so, h)
    n = q.shape[0]
    terms = (so[:n], so[n + 2], sw[MK.F], so[n], so[n + 3], so[n + 1])
    bank_update(obs, terms, tau_ext, q, qd, tau, finite, dt)
    return finite


@K.jit
def fused_tick(
    hot: np.ndarray,
    obs: Any,
    tx: np.ndarray,
    rx: np.ndarray,
    rec: np.ndarray,
    t_loop: float,
    dt: float,
    sdt: float,
    tick: int,
    wake: float,
    comp: float,
    quiet: bool,
) -> int:
    """One tick after the exchange (module docstring) on the tick's hot record ``hot`` (1,)
    (:func:`hot_dtype`), the observer bank's tuple ``obs``, the process images' bytes ``tx``,
    ``rx`` and the tick record ``rec`` (1,), for loop time ``t_loop`` [s], ``dt`` [s] since the
    last tick, the bus's sample interval ``sdt`` [s] (0: unknown, -1: no sample), tick number
    ``tick`` and the loop's wake-up and compute times [µs]. Sections 1-3 run on every call;
    the rest only when the caller found the tick ``quiet``. Returns the stage code where the
    Python stages go on."""
    h = hot[0]
    ts = h["tick"]
    tau_ext, prev, q_sent, tau_ff = ts["tau_ext"], ts["prev"], ts["q_sent"], ts["tau_ff"]
    si, states = h["si"], h["states"]
    # 1-2. the drive read (the exchange is the caller's)
    read_si(tx, si, states)
    sample = si[:3]
    q, qd = si[0], si[1]
    # 3. snapshot and observers over the sample interval: the bus's when it knows it (DC: the
    # drives sample at their own clock), else dt; held over a lost sample (sdt < 0: a repeated
    # sample integrated as new reads as a contact); after a stall the gap in one-cycle steps
    # from the last sample (each observer is tuned, and stable, for one cycle)
    period = ts["period"]
    obs_dt = 0.0
    if sdt >= 0.0:
        obs_dt = sdt if sdt > 0.0 else dt
        sw, so, sh = h["snap_w"], h["snap_o"], ts["snap_h"]
        k = 1 if obs_dt <= ts["stall"] else _gap_steps(obs_dt, period)
        if k == 1:
            finite = _observe(obs, sw, so, sh, tau_ext, sample, obs_dt)
        else:
            x = ts["interp"]
            for s in range(1, k + 1):
                a = s / k
                for i in range(3):
                    _lerp(prev[i], sample[i], a, x[i])
                finite = _observe(obs, sw, so, sh, tau_ext, x, obs_dt / k)
        for i in range(3):
            for j in range(q.shape[0]):
                prev[i, j] = sample[i, j]
        ts["finite"] = finite
    cmd_dt = _command_dt(dt, period)
    t_cmd = ts["t_cmd"] + cmd_dt
    ts["t_cmd"], ts["cmd_dt"] = t_cmd, cmd_dt
    ts["sample_dt"] = obs_dt
    if not quiet or sdt < 0.0:
        return SAFETY
    finite = ts["finite"]
    # 4. safety (good data: the caller checked the status; no fault latched or active)
    expect = ts["expect"]
    if drive_scan(states, ts["fault_min"], ts["op_enabled"] if expect else -1) >= 0:
        return SAFETY
    if not finite:
        return SAFETY
    ms = h["motion"]
    mq, mqd, mqdd, q0 = ms["q"], ms["qd"], ms["qdd"], ms["q0"]
    flags = tick_flags(tau_ext, states, POWERED, mqdd, rec[0]["qdd_cmd"])
    if not flags & ESTIMATES_FINITE:
        return SAFETY
    gap = _jump_gap(ts["since_fresh"] + dt, period)
    if limits_quiet(sample, q_sent, h["lim"], 1 + 2 * expect, gap) == 0:
        return SAFETY
    ts["since_fresh"] = 0.0  # good data (what bus.check and Tick._safety do on it)
    monitored = ts["has_coll"] and _judged(tick, ts["judge_from"], flags)
    if monitored != ts["monitored"]:
        ts["monitored"] = monitored
        rec[0]["monitored"] = monitored
    ts["mflags"] = 0
    if monitored:
        mdt = obs_dt if obs_dt > 0.0 else dt
        c = h["coll"]
        bbuf = h["bbuf"].view(np.bool_)  # numba has no boolean subarray fields: uint8 bytes
        f = monitor_tick(c["fbuf"], bbuf, c["first_tick"], tau_ext, qd, mqdd, mdt, tick)
        ts["mflags"] = f
        if f != 0 or ts["was_contact"]:
            return MONITOR
        if ts["has_learn"]:
            lrn = h["learn"]
            friction_learn(
                qd, tau_ext[ts["l_row"]], mdt, ts["l_vs"], ts["l_tau"], ts["l_min"],
                ts["l_every"], lrn["S"], lrn["b"], lrn["st"],
            )  # fmt: skip
    # 5. controller (HOLD at rest: nothing; MOVE: the demo path)
    kind = ts["kind"]
    if kind == OTHER:
        return CONTROL
    moved = kind == MOVE_PATH
    if moved:
        t = t_cmd - ts["t0"]
        # the exponent 2 from the state: the compiler cannot turn libm's pow into x·x
        b, bd, bdd = _fade_in(t, ts["ramp"], ts["two"])
        path_eval(h["path"], t, b, bd, bdd, q0, mq, mqd, mqdd)
        # the feed-forward: when the reference moved
        inverse_dynamics_native(mq, mqd, mqdd, h["ff_w"], tau_ff, ts["ff_h"])
    # 6. command (CSP with the torque offset)
    command_raw(mq, tau_ff, rx, si, 2)
    # 7. the record (and q_sent = the command just sent)
    fill_tick(
        rec, sample, mq, tau_ext, q_sent, t_loop, tick, ts["mode"], np.int64(0),
        np.int64(0), wake, comp, obs_dt,
    )  # fmt: skip
    return DONE


def hot_dtype(t: Tick) -> np.dtype:
    """The tick's one hot record: its state (:func:`tick_state_dtype`) and, as fields of
    their own dtypes and shapes, the hot arrays of its parts (:func:`hot_arrays`). Every
    field starts on a 16-byte boundary: a part's record dtype is packed (alignment 1), and
    an array moved to an unaligned address would be another type to numba (a compile in the
    loop at its first call from Python) and slower to numpy."""
    names, formats, offsets, at = [], [], [], 0
    for name, arr in [("tick", t.state), *hot_arrays(t)]:
        if arr.dtype.names:  # a part's record (1,): a nested record field
            fmt = arr.dtype
        else:  # numba has no boolean subarray fields: booleans as their bytes
            fmt = np.dtype((np.uint8 if arr.dtype == np.bool_ else arr.dtype, arr.shape))
        at = -(-at // 16) * 16
        names.append(name)
        formats.append(fmt)
        offsets.append(at)
        at += fmt.itemsize
    size = -(-at // 16) * 16
    return np.dtype({"names": names, "formats": formats, "offsets": offsets, "itemsize": size})


def hot_arrays(t: Tick) -> list[tuple[str, np.ndarray]]:
    """The parts' arrays the fused call reads and writes (name: the hot record's field), and
    the owners that may hold views of them (:func:`relocate`'s ``holders``)."""
    g, snap, ff, m = t.group, t.snapshot, t.feedforward, t.motion
    out = [
        ("si", g._si), ("states", g.states), ("snap_w", snap._W), ("snap_o", snap._O),
        ("ff_w", ff._W), ("lim", t.limits._w), ("motion", m.state),
    ]  # fmt: skip
    c = t.collision
    # absent parts: small stand-ins of the right types (the call checks has_coll/has_learn)
    if c is not None:
        out += [("coll", c.state.record), ("bbuf", c.state.bbuf)]
    else:
        k = max(1, len(t.observers))
        stand = np.dtype([("fbuf", np.float64, (1,)), ("first_tick", np.int64, (k,))])
        out += [("coll", np.zeros(1, stand)), ("bbuf", np.zeros(1, dtype=bool))]
    fr = _learning(t)
    if fr is not None:
        out.append(("learn", fr.record))
    else:
        n = t.n
        stand = np.dtype([("S", np.float64, (n, 3, 3)), ("b", np.float64, (n, 3)),
                          ("st", np.float64, (3,))])  # fmt: skip
        out.append(("learn", np.zeros(1, stand)))
    p = m.path
    out.append(("path", p._k if _path_ok(p) else np.zeros((1, t.n))))
    return out


def _learning(t: Tick) -> Any:
    """The drag's friction learning the tick runs outside drag mode, or None."""
    if t._learn is not None and t.drag is not None:
        return t.drag.friction
    return None


def _path_ok(p: Any) -> bool:
    """``p`` is a demo path the fused call evaluates (its compiled form)."""
    return p is not None and p._use_kernel and p._eval is path_eval


def _holders(t: Tick) -> list[Any]:
    """Every object that may hold a view of a hot array (its attributes, tuples, partials)."""
    snap, ff = t.snapshot, t.feedforward
    out = [t, t.group, snap, getattr(snap, "data", None), ff, t.limits, t.motion]
    out += [t.motion.path, t.collision, getattr(t.collision, "state", None)]
    out += [t.drag, _learning(t)]
    return [o for o in out if o is not None]


def relocate(t: Tick, hot: np.ndarray) -> list[tuple[Any, str, np.ndarray]]:
    """Move the tick's state and its parts' hot arrays into ``hot`` (a zeroed (1,) record of
    :func:`hot_dtype`): each array's numbers are copied into its field, and every attribute of
    the holders (:func:`_holders`) that views one of them (an array, a tuple's or a partial's
    array) is replaced by the same view into ``hot`` (one new view per old one: identities
    between the parts stay). Returns (owner, attribute, array) of each part's array, which
    :meth:`FusedTick.bound` checks later."""
    buf = hot.view(np.uint8)
    base = hot.ctypes.data
    olds = [("tick", t.state)] + hot_arrays(t)
    fields = [hot[name][0] if old.dtype.names is None else hot[name] for name, old in olds]
    spans = [
        (old.ctypes.data, old.ctypes.data + old.nbytes, f.ctypes.data - base)
        for (_, old), f in zip(olds, fields, strict=True)
    ]
    for owner in _holders(t):  # before anything moves: a view we could not rebind
        for attr, v in getattr(owner, "__dict__", {}).items():
            for x in v if isinstance(v, list | set) else v.values() if isinstance(v, dict) else ():
                if isinstance(x, np.ndarray) and any(
                    lo <= x.ctypes.data < hi for lo, hi, _ in spans
                ):
                    raise ValueError(
                        f"{type(owner).__name__}.{attr} holds a hot array in a container"
                    )
    for (_, old), f in zip(olds, fields, strict=True):
        np.copyto(f.view(old.dtype) if f.dtype != old.dtype else f, old)
    memo: dict[int, tuple[Any, Any]] = {}

    def moved(v: Any) -> Any:
        if isinstance(v, np.ndarray) and v.nbytes:
            if id(v) in memo:
                return memo[id(v)][1]
            p = v.ctypes.data
            for lo, hi, at in spans:
                if lo <= p < hi:
                    nv = np.ndarray(v.shape, v.dtype, buf, at + p - lo, v.strides)
                    memo[id(v)] = (v, nv)
                    return nv
            return v
        if isinstance(v, tuple):
            new = tuple(moved(x) for x in v)
            return new if any(a is not b for a, b in zip(new, v, strict=True)) else v
        if isinstance(v, partial):
            args = moved(v.args)
            return v if args is v.args else partial(v.func, *args, **v.keywords)
        return v

    for owner in _holders(t):
        for attr, v in list(getattr(owner, "__dict__", {}).items()):
            nv = moved(v)
            if nv is not v:
                setattr(owner, attr, nv)
    t.st = t.state[0]
    g, snap, ff, c, fr, m = t.group, t.snapshot, t.feedforward, t.collision, _learning(t), t.motion
    kept = [(t, "state"), (g, "_si"), (g, "states"), (snap, "_W"), (snap, "_O"), (ff, "_W")]
    kept += [(t.limits, "_w"), (m, "state")]
    if c is not None:
        kept += [(c.state, "record"), (c.state, "bbuf")]
    if fr is not None:
        kept.append((fr, "record"))
    if _path_ok(m.path):
        kept.append((m.path, "_k"))
    return [(o, a, getattr(o, a)) for o, a in kept]


_SAID: list[str] = []


def say_once(line: str) -> None:
    """Print ``line`` on stderr once per process (why the tick runs without the fused call)."""
    if not _SAID:
        _SAID.append(line)
        print(f"hofto-hw: {line}", file=sys.stderr)


class FusedTick:
    """The fused call's arguments for one :class:`~hofto_hw.runtime.tick.Tick`: its hot
    record, into which the tick's state and its parts' hot arrays are moved when this is
    built (``why`` says why not when ``ok`` is False; then nothing was moved)."""

    def __init__(self, tick: Tick) -> None:
        self.tick = tick
        self.why = self._check(tick)
        self.ok = not self.why
        self.path: Any = None
        self.kept: list[tuple[Any, str, np.ndarray]] = []
        if self.ok:
            self.hot = np.zeros(1, hot_dtype(tick))
            try:
                self.kept = relocate(tick, self.hot)
            except ValueError as exc:
                self.ok, self.why = False, f"the hot record cannot take over: {exc}"
                return
            # a new bank: its model terms and output rows are views of the moved arrays
            tick._bank = ObserverBank(tick.observers, tick.snapshot, tick.tau_ext)
            try:
                self._warm()
            except Exception as exc:  # numba's TypingError/LoweringError, a cache problem
                self.ok = False
                self.why = f"compiling the fused tick failed ({type(exc).__name__})"

    def bound(self) -> bool:
        """The parts still hold the arrays moved into the hot record (a part that replaced
        one, e.g. a snapshot rebuilt for a new model, needs a new FusedTick)."""
        return all(getattr(o, a) is arr for o, a, arr in self.kept)

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
        bank = t._bank
        if not (bank._any and bank._only) or bank._kernel is not bank_update:
            return "an observer is not fused in the bank: " + ", ".join(bank.rest)
        if t._flags is not tick_flags or t._fill is not fill_tick:
            return "the tick's flags and record fill run as Python"
        if not t.bus._use_kernel or not t.limits._use_kernel:
            return "the drive scan or the limit checks run their numpy path"
        c = t.collision
        if c is not None and not c._use_kernel:
            return "the collision monitor runs its numpy path"
        fr = _learning(t)
        if fr is not None and not fr._use_kernel:
            return "the friction learning runs its numpy path"
        ff = t.feedforward
        if ff._native is None or ff._id_native is not inverse_dynamics_native:
            return "the feed-forward does not run the native RNEA"
        return ""

    def args(self) -> tuple[Any, ...]:
        """The call's arguments before this tick's scalars, and the parts' constants into the
        tick's state (:attr:`path_ok`: the motion's path is the compiled one moved here)."""
        t = self.tick
        g, m, st = t.group, t.motion, t.st
        st["fault_min"], st["op_enabled"] = t.bus.fault_min, t.bus.op_enabled
        st["snap_h"] = t.snapshot._native.handle  # type: ignore[union-attr]
        st["ff_h"] = t.feedforward._native.handle  # type: ignore[union-attr]
        st["has_coll"] = t.collision is not None
        fr = _learning(t)
        st["has_learn"] = fr is not None
        if fr is not None:
            st["l_row"], st["l_vs"], st["l_tau"] = t.drag_row, fr.v_s, fr.tau
            st["l_min"], st["l_every"] = fr.min_speed, fr.every
        p = self.path = m.path
        self.path_ok = _path_ok(p) and self.hot_path(p)
        if self.path_ok:
            st["ramp"] = p.ramp
        return (self.hot, t._bank.args, g._tx_bytes, g._rx_bytes, t._rec1)

    def hot_path(self, p: Any) -> bool:
        """The path's workspace is the one moved into the hot record."""
        return any(o is p and a == "_k" and arr is p._k for o, a, arr in self.kept)

    def _warm(self) -> None:
        """Compile the kernel (all of it) with a lost sample, which returns after the drive
        read, here on a copy of the hot record: no state of the tick is touched."""
        hot, obs, tx, rx, rec = self.args()
        # a lost sample (sdt -1) on a tick that is not quiet: the read into the copy's rows,
        # then SAFETY; the argument types the tick passes (Tick.step)
        fused_tick(hot.copy(), obs, tx, rx, rec, 0.0, 0.0, -1.0, 0, 0.0, 0.0, False)
