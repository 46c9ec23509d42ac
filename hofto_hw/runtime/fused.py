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

Arguments: one int64 table of addresses and sizes (``A_*``; :class:`FusedTick` builds it from
the tick's own arrays, as the observer bank does, and :meth:`FusedTick.bound` checks they are
still the arrays their owners hold; among them the tick's float64 register of scalars,
``R_*``), the tick record (a one-element structured array) and this tick's scalars (loop
time, dt, the bus's sample interval, tick number, the loop's timings) as plain arguments:
numba passes a float argument for ~20 ns where a register write from Python costs ~50.
"""

from __future__ import annotations

import math
import sys
from typing import TYPE_CHECKING, Any

import numpy as np

from drivers.cia402.kernels import command_raw, read_si
from hofto_hw.control.joint_motion import FADED_IN, fade_terms
from hofto_hw.control.kernels import friction_learn, path_eval
from hofto_hw.model.kernels import inverse_dynamics_native, snapshot_native
from hofto_hw.observers import kernels as K
from hofto_hw.observers.kernels import bank_update
from hofto_hw.recording.kernels import fill_tick
from hofto_hw.runtime.tick_kernels import ESTIMATES_FINITE, POWER_ON, tick_flags
from safety.collision.kernel import monitor_tick
from safety.kernels import drive_scan, limits_quiet

if TYPE_CHECKING:
    from hofto_hw.runtime.tick import Tick

_fade_terms = K.jit(fade_terms)  # the demo path's fade-in arithmetic, compiled: one definition

#: stage codes (fused_tick's answer): where the Python reference goes on with this tick
READ = 0  # only the drive read was done: the reference from the snapshot on (section 3)
SAFETY = 1  # sections 1-3b done: the reference from the safety checks on (section 4)
MONITOR = 2  # the monitor ran and flagged: its report, then the reference from there on
CONTROL = 3  # section 4 done, nothing reported: the reference from the controller on (5)
DONE = 4  # everything but the sink's push (and the diagnostics record)
STAGES = ("read", "safety", "monitor", "control", "done")

# the table (int64): addresses [A_*] and sizes
(A_N, A_K, A_TX, A_TXLEN, A_SI, A_SIROWS, A_STATES, A_SW, A_SWROWS, A_SO, A_SH, A_BTAB,
 A_BROWS, A_BCOLS, A_TAUEXT, A_POWERED, A_NPOW, A_QDD, A_QDDREC, A_FAULTMIN, A_OPEN, A_LIMW,
 A_LIMROWS, A_LIMCOLS, A_QSENT, A_COLL, A_FBUF, A_FLEN, A_BBUF, A_BLEN, A_FIRST, A_LEARN,
 A_DRAGEST, A_LS, A_LB, A_LST, A_LEVERY, A_PK, A_PKROWS, A_Q0, A_MQ, A_MQD, A_MQDD, A_IDW,
 A_IDWROWS, A_TAUFF, A_IDH, A_RX, A_RXLEN, A_PREV, A_REG) = range(51)  # fmt: skip
A_SIZE = 51

# the register (float64): the tick's kept scalars, constants, outputs (this tick's own
# scalars are the call's arguments)
(R_TCMD, R_SINCE, R_JUDGE, R_EXPECT, R_KIND, R_FFSTALE, R_WAS_CONTACT, R_REC_MON, R_PERIOD,
 R_STALL, R_T0, R_RAMP, R_VS, R_LTAU, R_LMIN, R_MODE, R_OBS_DT, R_FINITE, R_MFLAGS, R_FF,
 R_MON, R_TWO) = range(22)  # fmt: skip
R_SIZE = 22

#: R_KIND: the motion's update this tick (HOLD_STILL: nothing to write; MOVE_PATH: the
#: compiled demo path; OTHER: the reference runs the controller)
HOLD_STILL, MOVE_PATH, OTHER = 0, 1, 2

# pointers at the table's addresses (the observer bank's helper, one per element type)
_f64 = K.pointer_at("float64")
_u8 = K.pointer_at("uint8")
_i64 = K.pointer_at("int64")
_b1 = K.pointer_at("boolean")
_carray = K.carray


@K.jit
def fused_tick(
    a: np.ndarray,
    rec: np.ndarray,
    t_loop: float,
    dt: float,
    sdt: float,
    tick: int,
    wake: float,
    comp: float,
) -> int:
    """One tick's common path (module docstring) on the table ``a`` (the register at
    ``a[A_REG]``) and the tick record ``rec`` (1,), for loop time ``t_loop`` [s], ``dt`` [s]
    since the last tick, the bus's sample interval ``sdt`` [s] (0: unknown, -1: no sample),
    tick number ``tick`` and the loop's wake-up and compute times [µs]. Returns the stage code
    where the reference goes on."""
    n = a[A_N]
    r = _carray(_f64(a[A_REG]), (R_SIZE,))
    # 1-2. the drive read (the exchange is the caller's)
    si = _carray(_f64(a[A_SI]), (a[A_SIROWS], n))
    states = _carray(_u8(a[A_STATES]), (n,))
    read_si(_carray(_u8(a[A_TX]), (a[A_TXLEN],)), si, states)
    sample = si[:3]
    q, qd, tau = si[0], si[1], si[2]
    if sdt < 0.0:
        return READ  # a lost sample: the reference holds the observers
    obs_dt = sdt if sdt > 0.0 else dt
    if not obs_dt <= r[R_STALL]:
        return READ  # a stall: the reference integrates the gap in sub-steps
    # 3. snapshot and observers
    finite = snapshot_native(
        q,
        qd,
        tau,
        _carray(_f64(a[A_SW]), (a[A_SWROWS], n)),
        _carray(_f64(a[A_SO]), (n + 4, n)),
        a[A_SH],
    )
    tau_ext = _carray(_f64(a[A_TAUEXT]), (a[A_K], n))
    btab = _carray(_i64(a[A_BTAB]), (a[A_BROWS], a[A_BCOLS]))
    bank_update(btab, q, qd, tau, finite, obs_dt)
    prev = _carray(_f64(a[A_PREV]), (3, n))
    for i in range(3):
        for j in range(n):
            prev[i, j] = sample[i, j]
    period = r[R_PERIOD]
    cmd_dt = dt if period <= 0.0 or dt <= period else period  # tick.command_dt
    t_cmd = r[R_TCMD] + cmd_dt
    r[R_TCMD] = t_cmd
    r[R_OBS_DT] = obs_dt
    r[R_FINITE] = 1.0 if finite else 0.0
    # 4. safety (good data: the caller checked the status; no fault latched or active)
    expect = r[R_EXPECT] != 0.0
    if drive_scan(states, a[A_FAULTMIN], a[A_OPEN] if expect else -1) >= 0:
        return SAFETY
    if not finite:
        return SAFETY
    mqdd = _carray(_f64(a[A_MQDD]), (n,))
    flags = tick_flags(
        tau_ext,
        states,
        _carray(_u8(a[A_POWERED]), (a[A_NPOW],)),
        mqdd,
        _carray(_f64(a[A_QDDREC]), (n,)),
    )
    if not flags & ESTIMATES_FINITE:
        return SAFETY
    q_sent = _carray(_f64(a[A_QSENT]), (n,))
    gap = r[R_SINCE] + dt - period if period > 0.0 else 0.0
    limw = _carray(_f64(a[A_LIMW]), (a[A_LIMROWS], a[A_LIMCOLS]))
    if limits_quiet(sample, q_sent, limw, 1 + 2 * expect, gap if gap > 1e-9 else 0.0) == 0:
        return SAFETY
    r[R_SINCE] = 0.0  # good data (what bus.check and Tick._safety do on it)
    settled = tick >= r[R_JUDGE]
    monitored = a[A_COLL] != 0 and settled and flags & POWER_ON != 0
    mon = 1.0 if monitored else 0.0
    r[R_MON] = mon
    if mon != r[R_REC_MON]:
        r[R_REC_MON] = mon
        rec[0].monitored = monitored
    r[R_MFLAGS] = 0.0
    if monitored:
        mdt = obs_dt if obs_dt > 0.0 else dt
        f = monitor_tick(
            _carray(_f64(a[A_FBUF]), (a[A_FLEN],)),
            _carray(_b1(a[A_BBUF]), (a[A_BLEN],)),
            _carray(_i64(a[A_FIRST]), (a[A_K],)),
            tau_ext,
            qd,
            mqdd,
            mdt,
            tick,
        )
        r[R_MFLAGS] = f
        if f != 0 or r[R_WAS_CONTACT] != 0.0:
            return MONITOR
        if a[A_LEARN] != 0:
            friction_learn(
                qd,
                _carray(_f64(a[A_DRAGEST]), (n,)),
                mdt,
                r[R_VS],
                r[R_LTAU],
                r[R_LMIN],
                a[A_LEVERY],
                _carray(_f64(a[A_LS]), (n, 3, 3)),
                _carray(_f64(a[A_LB]), (n, 3)),
                _carray(_f64(a[A_LST]), (3,)),
            )
    # 5. controller (HOLD at rest: nothing; MOVE: the demo path)
    kind = r[R_KIND]
    if kind == OTHER:
        return CONTROL
    mq = _carray(_f64(a[A_MQ]), (n,))
    mqd = _carray(_f64(a[A_MQD]), (n,))
    moved = kind == MOVE_PATH
    if moved:
        t = t_cmd - r[R_T0]
        ramp = r[R_RAMP]
        b, bd, bdd = 1.0, 0.0, -0.0  # joint_motion.FADED_IN
        if not t >= ramp:
            # joint_motion.fade_in: (1 - x)**2 is libm's pow in Python; the exponent comes
            # from the register so that the compiler cannot turn pow into x·x (not the bits)
            x = min(max(t / ramp, 0.0), 1.0)
            b, bd, bdd = _fade_terms(x, math.pow(1.0 - x, r[R_TWO]), ramp)
        pk = _carray(_f64(a[A_PK]), (a[A_PKROWS], n))
        path_eval(pk, t, b, bd, bdd, _carray(_f64(a[A_Q0]), (n,)), mq, mqd, mqdd)
    # the feed-forward: when the reference moved or the caller says it is stale
    tau_ff = _carray(_f64(a[A_TAUFF]), (n,))
    r[R_FF] = 0.0
    if moved or r[R_FFSTALE] != 0.0:
        inverse_dynamics_native(
            mq, mqd, mqdd, _carray(_f64(a[A_IDW]), (a[A_IDWROWS], n)), tau_ff, a[A_IDH]
        )
        r[R_FF] = 1.0
    # 6. command (CSP with the torque offset)
    command_raw(mq, tau_ff, _carray(_u8(a[A_RX]), (a[A_RXLEN],)), si, 2)
    # 7. the record (and q_sent = the command just sent)
    fill_tick(
        rec, sample, mq, tau_ext, q_sent, t_loop, tick, np.int64(r[R_MODE]), np.int64(0),
        np.int64(0), wake, comp, obs_dt,
    )  # fmt: skip
    return DONE


def _entry_point(tab: np.ndarray, rec: np.ndarray) -> Any:
    """:func:`fused_tick`'s compiled overload for a tick's table and record (and the scalar
    types :meth:`Tick._fused_step` passes), called without numba's dispatch on argument types:
    ~0.3 µs less a call (tools/bench_tick.py), and the types cannot change (the table and
    the record are the tick's own, built once; an int where a float is expected converts
    instead of compiling again). The dispatcher itself when numba does not offer it."""
    try:
        typeof = K._numba.typeof
        key = (typeof(tab), typeof(rec)) + tuple(typeof(x) for x in (0.0, 0.0, 0.0, 0, 0.0, 0.0))
        entry = fused_tick.overloads[key].entry_point
    except (AttributeError, KeyError, TypeError):
        return fused_tick
    return entry if callable(entry) else fused_tick


_SAID: list[str] = []


def say_once(line: str) -> None:
    """Print ``line`` on stderr once per process (why the tick runs without the fused call)."""
    if not _SAID:
        _SAID.append(line)
        print(f"hofto-hw: {line}", file=sys.stderr)


def _fit(arr: Any, dtype: Any, shape: tuple[int, ...]) -> bool:
    return (
        isinstance(arr, np.ndarray)
        and arr.dtype == dtype
        and arr.shape == shape
        and arr.flags.c_contiguous
        and arr.flags.writeable
    )


class FusedTick:
    """The fused call's table and register for one :class:`~hofto_hw.runtime.tick.Tick`
    (built from its arrays; ``why`` says why not when ``ok`` is False)."""

    def __init__(self, tick: Tick) -> None:
        self.tick = tick
        self.reg = tick._reg
        self.tab = np.zeros(A_SIZE, dtype=np.int64)
        self._keep: list[tuple[object, str, np.ndarray]] = []
        self.why = self._build(tick)
        self.ok = not self.why
        #: what the tick calls: the compiled overload for its table and record
        self.call: Any = fused_tick
        if self.ok:
            try:
                self._warm()
            except Exception as exc:  # numba's TypingError/LoweringError, a cache problem
                self.ok = False
                self.why = f"compiling the fused tick failed ({type(exc).__name__})"
            else:
                self.call = _entry_point(self.tab, tick._rec1)

    # ---------------------------------------------------------------- building

    def _put(self, slot: int, owner: object, attr: str, dtype: Any, shape: tuple[int, ...]) -> bool:
        arr = getattr(owner, attr, None) if attr else owner
        if not _fit(arr, dtype, shape):
            return False
        assert isinstance(arr, np.ndarray)
        self._keep.append((owner if attr else None, attr, arr))
        self.tab[slot] = arr.ctypes.data
        return True

    def bound(self) -> bool:
        """The arrays the table addresses are still the ones their owners hold."""
        return all(getattr(o, a) is arr for o, a, arr in self._keep if o is not None)

    def _build(self, t: Tick) -> str:
        """Fill the table; '' when every part can be fused, else why not."""
        if not K.available():
            return "the fused tick needs numba (" + K.unavailable_reason() + ")"
        g, a, r, f64, u8 = t.group, self.tab, self.reg, np.float64, np.uint8
        n, k = t.n, t.tau_ext.shape[0]
        a[A_N], a[A_K] = n, k
        if not self._put(A_REG, t, "_reg", f64, (R_SIZE,)):
            return "the tick's register is not a plain array"
        if g._fast is None:
            return "the drive group runs its numpy path"
        si = g._si
        if not (g.sample.base is si and g.sample.ctypes.data == si.ctypes.data):
            return "the drive group's sample is not its workspace's first rows"
        if not g.q.ctypes.data == si.ctypes.data:
            return "the drive group's q is not its workspace's row"
        a[A_SIROWS] = si.shape[0]
        a[A_TXLEN], a[A_RXLEN] = g._tx_bytes.shape[0], g._rx_bytes.shape[0]
        if not (
            self._put(A_SI, g, "_si", f64, si.shape)
            and self._put(A_STATES, g, "states", u8, (n,))
            and self._put(A_TX, g, "_tx_bytes", u8, g._tx_bytes.shape)
            and self._put(A_RX, g, "_rx_bytes", u8, g._rx_bytes.shape)
        ):
            return "the drive group's images are not plain arrays"
        snap = t.snapshot
        if snap.model is not t.feedforward.model:
            return "the snapshot and the feed-forward use different models"
        if snap._native is None:
            return "the snapshot does not run the native dynamics"
        a[A_SWROWS], a[A_SH] = snap._W.shape[0], snap._native.handle
        if not (
            self._put(A_SW, snap, "_W", f64, snap._W.shape)
            and self._put(A_SO, snap, "_O", f64, (n + 4, n))
        ):
            return "the snapshot's workspace is not a plain array"
        bank = self.bank = t._bank
        if not (bank._any and bank._only) or bank._kernel is not bank_update:
            return "an observer is not fused in the bank: " + ", ".join(bank.rest)
        a[A_BROWS], a[A_BCOLS] = bank._tab.shape
        if not (
            self._put(A_BTAB, bank, "_tab", np.int64, bank._tab.shape)
            and self._put(A_TAUEXT, t, "tau_ext", f64, (k, n))
            and self._put(A_PREV, t, "_prev", f64, (3, n))
            and self._put(A_QSENT, t, "q_sent", f64, (n,))
        ):
            return "the tick's arrays are not plain arrays"
        if t._flags is not tick_flags or not t._fill_kernel:
            return "the tick's flags and record run their numpy path"
        from hofto_hw.runtime.tick import _POWERED

        a[A_NPOW] = _POWERED.shape[0]
        self._keep.append((None, "", _POWERED))
        a[A_POWERED] = _POWERED.ctypes.data
        a[A_QDDREC] = t._qdd_rec.ctypes.data  # the record's field (kept by the record)
        bus, lim = t.bus, t.limits
        if not bus._use_kernel or not lim._use_kernel:
            return "the drive scan or the limit checks run their numpy path"
        a[A_FAULTMIN], a[A_OPEN] = bus.fault_min, bus.op_enabled
        a[A_LIMROWS], a[A_LIMCOLS] = lim._w.shape
        if not self._put(A_LIMW, lim, "_w", f64, lim._w.shape):
            return "the limit monitor's workspace is not a plain array"
        c = t.collision
        if c is not None:
            if not c._use_kernel or c._tool is not None:
                return "the collision monitor runs its numpy path or a tool-force check"
            s = c.state
            a[A_COLL], a[A_FLEN], a[A_BLEN] = 1, s.fbuf.shape[0], s.bbuf.shape[0]
            if not (
                self._put(A_FBUF, s, "fbuf", f64, s.fbuf.shape)
                and self._put(A_BBUF, s, "bbuf", np.bool_, s.bbuf.shape)
                and self._put(A_FIRST, s, "first_tick", np.int64, (k,))
            ):
                return "the collision monitor's state is not plain arrays"
        if t._learn is not None and t.drag is not None and t.drag.friction is not None:
            fr = t.drag.friction
            if not fr._use_kernel:
                return "the friction learning runs its numpy path"
            a[A_LEARN], a[A_LEVERY] = 1, fr.every
            r[R_VS], r[R_LTAU], r[R_LMIN] = fr.v_s, fr.tau, fr.min_speed
            if not (
                self._put(A_LS, fr, "S", f64, (n, 3, 3))
                and self._put(A_LB, fr, "b", f64, (n, 3))
                and self._put(A_LST, fr, "_st", f64, (3,))
            ):
                return "the friction learning's sums are not plain arrays"
            a[A_DRAGEST] = t._drag_est.ctypes.data  # a row of tau_ext
        m = t.motion
        if not (
            self._put(A_MQ, m, "q", f64, (n,))
            and self._put(A_MQD, m, "qd", f64, (n,))
            and self._put(A_MQDD, m, "qdd", f64, (n,))
            and self._put(A_Q0, m, "q0", f64, (n,))
        ):
            return "the motion's reference is not plain arrays"
        self.path_ok = False
        p = m.path
        if p is not None and p._use_kernel and p._eval is path_eval:
            a[A_PKROWS] = p._k.shape[0]
            self.path_ok = self._put(A_PK, p, "_k", f64, p._k.shape)
            r[R_RAMP] = p.ramp
        self.path = p
        ff = t.feedforward
        if ff._native is None or ff._id_native is not inverse_dynamics_native:
            return "the feed-forward does not run the native RNEA"
        a[A_IDWROWS], a[A_IDH] = ff._W.shape[0], ff._native.handle
        if not (
            self._put(A_IDW, ff, "_W", f64, ff._W.shape)
            and self._put(A_TAUFF, t, "tau_ff", f64, (n,))
        ):
            return "the feed-forward's workspace is not a plain array"
        r[R_PERIOD], r[R_STALL], r[R_TWO] = t.period, t._stall_dt, 2.0
        if FADED_IN != (1.0, 0.0, -0.0) or str(FADED_IN[2]) != "-0.0":
            return "the demo path's faded-in constants are not the ones the fused call uses"
        return ""

    def _warm(self) -> None:
        """Compile the kernel (all of it) with a lost sample, which returns after the drive
        read, here into scratch rows: no state of the tick is touched."""
        a, r = self.tab.copy(), self.reg.copy()
        si = self.tick.group._si.copy()
        states = self.tick.group.states.copy()
        a[A_SI], a[A_STATES] = si.ctypes.data, states.ctypes.data  # scratch read
        a[A_REG] = r.ctypes.data
        # a lost sample (sdt -1): the read into the scratch rows, then READ; the argument
        # types the tick passes (Tick._fused_step)
        fused_tick(a, self.tick._rec1, 0.0, 0.0, -1.0, 0, 0.0, 0.0)
