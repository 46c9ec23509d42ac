"""The tick after the exchange as one compiled call (numba), calling the parts' own kernels.

:func:`fused_tick` runs on every tick, the only place sections 1-3 run: the drive read
(``read_si``) and the dynamics snapshot and observers (``snapshot_native``,
``bank_update``) over the sample interval, a lost sample held and a stall integrated in
one-cycle sub-steps. Then section 4, the one place the safety checks are sequenced
(:func:`section4`, which it calls; after a Python pre-safety step the tick calls it itself):
the bus (``drive_scan``), the finiteness checks, the tick's flags (``tick_flags``), the
limits (``limits_scan``, ``limits_commit``), the collision monitor (``monitor_tick``) and
the friction learning (``friction_learn``). The checks report into the tick state's fault
array, never to the stop controller; Python turns it into reports
(``Tick._report_faults``). On a tick where nothing unusual can happen (the caller's
``quiet``) and section 4 found nothing it goes on into sections 5-7 (:func:`section57`, their
one sequencing, which the tick calls itself on every other tick after the Python stages' rare
decisions): the demo path (``path_eval``), the feed-forward (``inverse_dynamics_native``),
the hand's torque on it, the command (``command_raw``) and the record fill (``fill_tick``).
The flight recorder's push stays in Python (the tick's sink).

Otherwise the kernel returns the stage where the tick's Python takes over for the rest of
the SAME tick (the :data:`STAGES` codes); it has not written anything Python redoes from
there. tests/support/reference_tick.py runs every stage in Python on every tick, sections
1-4 through the parts' own methods: the reference the tests compare with.

Arguments: few, so that numba's dispatch unboxes little on every call (each array argument
costs ~0.1-0.3 µs, more with the caches cold after the exchange): the tick's one hot record
(:func:`hot_record`: the tick's state and the parts' hot arrays as its fields, allocated by
the composition root before the parts, which are built on their fields), the observer bank's
tuple (its observers' own records), the process images' bytes, the tick record (a
one-element structured array)
and this tick's scalars (loop time, dt, the bus's sample interval, tick number, the loop's
timings). Numba types each field by its dtype and shape; with numba's JIT switched off
(NUMBA_DISABLE_JIT=1) the same source runs as Python.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np

from drivers.cia402.kernels import command_raw, read_si
from hofto_hw import jit as K  # the project's jit: K.jit, K.available
from hofto_hw.control.joint_motion import DRAG, MOVE, fade_in
from hofto_hw.control.kernels import friction_learn, path_eval
from hofto_hw.model import kernels as MK
from hofto_hw.model.kernels import inverse_dynamics_native, snapshot_native
from hofto_hw.observers.kernels import bank_update
from hofto_hw.recording.kernels import fill_tick
from hofto_hw.runtime.tick_events import DRIVE_CAUSES
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
from safety.collision.state import COLLIDED, CONTACT, NONFINITE
from safety.kernels import (
    N_REPORTS,
    REPORT_JOINT,
    REPORT_VALUE,
    drive_scan,
    limits_commit,
    limits_scan,
)
from safety.limits import LIMIT_FAULTS
from safety.stop import N_FAULTS, Fault, commanded

if TYPE_CHECKING:
    from hofto_hw.runtime.tick import Tick

# the glue the Python stages compute, compiled from the same functions: one definition
_fade_in = K.jit(fade_in)
_command_dt = K.jit(command_dt)
_jump_gap = K.jit(jump_gap)
_judged = K.jit(judged)
_gap_steps = K.jit(gap_steps)
_commanded = K.jit(commanded)
_lerp = K.jit(lerp)

#: stage codes (the answer of fused_tick and of section4): where the tick's Python goes on
#: (after CONTROL: its stages, then section57)
SAFETY = 1  # sections 1-3 done; a pre-safety step is Python's (3b), then section4 (4)
BUS = 2  # the drive scan found an axis: Python names its fault (STO? brake?), section4 resumes
CONTROL = 3  # section 4 done, its findings in the fault array: their reports, then 4 (end)-7
DONE = 4  # everything but the sink's push (and the diagnostics record)
STAGES = {SAFETY: "safety", BUS: "bus", CONTROL: "control", DONE: "done"}

#: kinds of the fault array's entries besides the Fault codes (< N_FAULTS): the collision
#: monitor's flags (joint column; CollisionLevels._report turns them into reports) and the
#: tool-force check's value (reported when above its limit)
K_MONITOR, K_TOOL = 200, 201
_LIMIT_FAULTS = np.array([int(f) for f in LIMIT_FAULTS], dtype=np.int64)
_DRIVE_CAUSES = int(DRIVE_CAUSES)
_BUS_LOSS, _NON_FINITE = int(Fault.BUS_LOSS), int(Fault.NON_FINITE)
_COLLISION = int(Fault.COLLISION)
_MON_CONTACT = COLLIDED | CONTACT


def fault_cap(k: int) -> int:
    """Capacity of the fault array for k observer rows, every check reporting at once: the
    bus (1), the finiteness of q, qd, tau and of each estimate row (3 + k), the five limit
    classes, the monitor and the tool force."""
    return 1 + 3 + k + N_REPORTS + 2


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
            ("cats", i8, (N_FAULTS,)),  # the stop category of each fault class (-1: none)
            ("has_tool", b1),  # the collision monitor's tool-force check is configured
            ("tool_limit", f8),  # its limit [N]
            # section 4's inputs from Python (Tick._inputs, on a tick that is not quiet; a
            # quiet one takes them as: nothing latched or active, good data, no bus loss)
            ("s_latched", i8),  # the stop's latched, active and category, kept by section 4
            ("s_active", i8),  # as its findings would change them (StopController.report)
            ("s_cat", i8),
            ("good", b1),  # the exchange brought good data (status ok and fresh)
            ("bus_loss", b1),  # the bus's loss streak reached its limit (BusHealth.count)
            ("status", i8),  # the exchange's status
            ("enabling", b1),
            ("homing", b1),  # a homing run by the loop (the drive moves the axis)
            ("pre", b1),  # a pre-safety step is Python's (drag, homing, tool force)
            ("use_mon", b1),  # the monitor judges tau_mon (dragging), not tau_ext
            ("tool_value", f8),  # the tool force of this tick [N] (Python's pre-step)
            # what section 4 found: the fault array (kind, joint, value) in the order the
            # checks ran (the monitor's flags in its entry's joint column), the drive scan's
            # axis; the sample was finite
            ("nf", i8),
            ("fk", i8, (fault_cap(k),)),
            ("fj", i8, (fault_cap(k),)),
            ("fv", f8, (fault_cap(k),)),
            ("scan_j", i8),
            ("finite", b1),
            ("tau_ext", f8, (k, n)),  # the observers' estimates [N·m]
            ("tau_mon", f8, (k, n)),  # the monitor's input while dragging [N·m]
            ("prev", f8, (3, n)),  # last tick's q, qd, tau (a stall's interpolation start)
            ("interp", f8, (3, n)),  # one stall sub-step's q, qd, tau
            ("q_sent", f8, (n,)),  # position target of the last command [rad]
            ("tau_ff", f8, (n,)),  # the feed-forward torque [N·m]
            ("tau_off", f8, (n,)),  # the hand's torque while dragging (S_OFF) [N·m]
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
def _entry(ts: Any, kind: int, joint: int, value: float) -> None:
    """Append (kind, joint, value) to the fault array (its capacity covers every check)."""
    i = ts["nf"]
    if i < ts["fk"].shape[0]:
        ts["fk"][i], ts["fj"][i], ts["fv"][i] = kind, joint, value
        ts["nf"] = i + 1


@K.jit
def _effect(ts: Any, fault: int) -> None:
    """What StopController.report does to latched, active and category (the configured
    categories), on section 4's copies: later checks of the same tick read them."""
    bit = np.int64(1) << fault
    ts["s_active"] = ts["s_active"] | bit
    lat = ts["s_latched"]
    if lat & bit == 0:
        ts["s_latched"] = lat | bit
        ts["s_cat"] = _commanded(ts["s_cat"], ts["cats"][fault])


@K.jit
def _report(ts: Any, fault: int, joint: int, value: float) -> None:
    """A fault found: its entry and its effect (StopController.report's, in order)."""
    _entry(ts, fault, joint, value)
    _effect(ts, fault)


@K.jit
def _finite(ts: Any, x: np.ndarray) -> bool:
    """NON_FINITE on the first non-finite entry of ``x`` (n,); whether all were finite."""
    for j in range(x.shape[0]):
        if not math.isfinite(x[j]):
            _report(ts, _NON_FINITE, j, x[j])
            return False
    return True


@K.jit
def _quiet_inputs(ts: Any) -> None:
    """Section 4's inputs on a quiet tick: nothing latched or active, good data."""
    ts["s_latched"], ts["s_active"], ts["s_cat"] = 0, 0, -1
    ts["good"], ts["bus_loss"], ts["enabling"], ts["homing"] = True, False, False, False


@K.jit
def section4(hot: np.ndarray, rec: np.ndarray, tick: int, dt: float, resume: bool) -> int:
    """Section 4 of every tick, the one sequencing of the safety checks, on the hot record
    ``hot`` (1,) and the tick record ``rec`` (1,): the bus (loss streak, drive scan), the
    finiteness of the sample and of the estimates, the limits, the collision monitor (with the
    tool force) and the friction learning. Each finding goes into the fault array (``nf``
    entries) in the order the checks ran, with its effect on the stop's state that later
    checks read (``powered``, ``trusted``, the learning's "no stop"); Python turns the array
    into stop.report calls (Tick._report_faults). Called by :func:`fused_tick`, and by the
    tick's Python after a pre-safety step. Returns BUS when the drive scan found an axis (its
    fault is Python's to name; then called again with ``resume``), else CONTROL."""
    h = hot[0]
    ts = h["tick_state"]
    si, states = h["group_si"], h["group_states"]
    sample = si[:3]
    q, qd, tau = si[0], si[1], si[2]
    good = ts["good"]
    if not resume:
        ts["nf"] = 0
        if ts["bus_loss"]:
            _report(ts, _BUS_LOSS, -1, float(ts["status"]))
        if good:
            j = drive_scan(states, ts["fault_min"], ts["op_enabled"] if ts["expect"] else -1)
            if j >= 0:
                ts["scan_j"] = j
                return BUS
    # a finite snapshot sample means q, qd, tau are all finite (their sum is): the checks
    # that name the joint run only when something is not (each of the three: no short cut)
    ok = ts["finite"]
    if not ok:
        a, b, c = _finite(ts, q), _finite(ts, qd), _finite(ts, tau)
        ok = a and b and c
    tau_ext, ms = ts["tau_ext"], h["motion_state"]
    # the estimates' finiteness, the power stage, motion.qdd into the record
    flags = tick_flags(tau_ext, states, POWERED, ms["qdd"], rec[0]["qdd_cmd"])
    if not flags & ESTIMATES_FINITE:
        for i in range(tau_ext.shape[0]):
            if not _finite(ts, tau_ext[i]):
                ok = False
    cat = ts["s_cat"]
    powered = ts["expect"] and not ts["enabling"] and (cat == -1 or cat == 2)
    since = ts["since_fresh"] + dt
    ts["since_fresh"] = since
    how = (1 if good else 0) + (2 if powered else 0)
    w = h["lim_w"]
    if limits_scan(sample, ts["q_sent"], w, how, _jump_gap(since, ts["period"])) > 0:
        for c in range(N_REPORTS):  # in class order
            if w[REPORT_JOINT, c] >= 0.0:
                _report(ts, _LIMIT_FAULTS[c], int(w[REPORT_JOINT, c]), w[REPORT_VALUE, c])
    limits_commit(sample, w, how)
    if good:
        ts["since_fresh"] = 0.0
    # judged on trustworthy data only: fresh (a lost frame repeats the last sample) and from
    # drives that report no fault (a failed encoder freezes its position); an observer with
    # poles at a few hundred rad/s reads either as a contact; not while enabling or homing
    trusted = ok and good and ts["s_active"] & _DRIVE_CAUSES == 0
    trusted = trusted and not ts["enabling"] and not ts["homing"]
    monitored = ts["has_coll"] and trusted and _judged(tick, ts["judge_from"], flags)
    if monitored != ts["monitored"]:
        ts["monitored"] = monitored
        rec[0]["monitored"] = monitored  # replay judges the same ticks
    if monitored:
        # over the interval the observers integrated (DC: the drives' own; a stalled
        # master's dt made the acceleration feature, and the threshold, too small)
        obs_dt = ts["sample_dt"]
        mdt = obs_dt if obs_dt > 0.0 else dt
        est = ts["tau_mon"] if ts["use_mon"] else tau_ext
        cr = h["coll_record"]
        bbuf = h["coll_bbuf"].view(np.bool_)  # numba has no boolean subarray fields
        f = monitor_tick(cr["fbuf"], bbuf, cr["first_tick"], est, qd, ms["qdd"], mdt, tick)
        if f != 0 or ts["was_contact"]:  # CollisionLevels._report's findings, in its order
            _entry(ts, K_MONITOR, f, 0.0)
            if f & NONFINITE:
                _effect(ts, _NON_FINITE)
            if f & COLLIDED:
                _effect(ts, _COLLISION)
        if ts["has_tool"]:
            v = ts["tool_value"]
            _entry(ts, K_TOOL, -1, v)
            if v > ts["tool_limit"]:
                _effect(ts, _COLLISION)
        # the friction's error learned from contact-free motion (not dragging, no stop)
        if ts["has_learn"] and ts["mode"] != DRAG and ts["s_cat"] == -1 and f & _MON_CONTACT == 0:
            lrn = h["learn_record"]
            friction_learn(
                qd, tau_ext[ts["l_row"]], mdt, ts["l_vs"], ts["l_tau"], ts["l_min"],
                ts["l_every"], lrn["S"], lrn["b"], lrn["st"],
            )  # fmt: skip
    return CONTROL


#: :func:`section57`'s ``what`` bits: the steps of sections 5-6 this tick takes
S_PATH = 1  # 5. the demo path at t_cmd - t0 (MOVE on the compiled path)
S_FF = 2  # 5. the feed-forward of the reference (a new reference or a new model)
S_OFF = 4  # 5. the hand's torque (tau_off, dragging) added to the feed-forward


@K.jit
def section57(
    hot: np.ndarray,
    rx: np.ndarray,
    rec: np.ndarray,
    t_loop: float,
    tick: int,
    what: int,
    mode: int,
    latched: int,
    status: int,
    wake: float,
    comp: float,
) -> None:
    """Sections 5-7 of every tick, their one sequencing, on the hot record ``hot`` (1,), the
    output image's bytes ``rx`` and the tick record ``rec`` (1,): called by :func:`fused_tick`
    on a quiet tick, else by the tick's Python after its rare decisions (the stop category's
    drive commands, mode changes, enabling, the drag's follow, playback, the ramp, teach
    recording: they wrote the motion's reference). The demo path (``what`` & S_PATH), the
    feed-forward (S_FF) and the hand's torque on it (S_OFF), the command (CSP with the torque
    offset) and the tick record (q_sent = the command just sent) with the motion's ``mode``,
    the stop's ``latched`` faults, the exchange's ``status`` and the loop's timings [µs]. The
    sink's push is Python's."""
    h = hot[0]
    ts = h["tick_state"]
    ms = h["motion_state"]
    mq, mqd, mqdd = ms["q"], ms["qd"], ms["qdd"]
    tau_ff = ts["tau_ff"]
    if what & S_PATH:
        t = ts["t_cmd"] - ts["t0"]
        # the exponent 2 from the state: the compiler cannot turn libm's pow into x·x
        b, bd, bdd = _fade_in(t, ts["ramp"], ts["two"])
        path_eval(h["path_k"], t, b, bd, bdd, ms["q0"], mq, mqd, mqdd)
    if what & S_FF:
        inverse_dynamics_native(mq, mqd, mqdd, h["ff_W"], tau_ff, ts["ff_h"])
    if what & S_OFF:
        off = ts["tau_off"]
        for j in range(tau_ff.shape[0]):
            tau_ff[j] += off[j]
    # 6. command (CSP with the torque offset)
    command_raw(mq, tau_ff, rx, h["group_si"], 2)
    # 7. the record (and q_sent = the command just sent)
    fill_tick(
        rec, h["group_si"][:3], mq, ts["tau_ext"], ts["q_sent"], t_loop, tick, mode,
        np.int64(latched), np.int64(status), wake, comp, ts["sample_dt"],
    )  # fmt: skip


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
    (:func:`hot_record`), the observer bank's tuple ``obs``, the process images' bytes ``tx``,
    ``rx`` and the tick record ``rec`` (1,), for loop time ``t_loop`` [s], ``dt`` [s] since the
    last tick, the bus's sample interval ``sdt`` [s] (0: unknown, -1: no sample), tick number
    ``tick`` and the loop's wake-up and compute times [µs]. Sections 1-3 run on every call;
    the rest only when the caller found the tick ``quiet``. Returns the stage code where the
    Python stages go on."""
    h = hot[0]
    ts = h["tick_state"]
    tau_ext, prev = ts["tau_ext"], ts["prev"]
    si, states = h["group_si"], h["group_states"]
    # 1-2. the drive read (the exchange is the caller's)
    read_si(tx, si, states)
    sample = si[:3]
    q = si[0]
    # 3. snapshot and observers over the sample interval: the bus's when it knows it (DC: the
    # drives sample at their own clock), else dt; held over a lost sample (sdt < 0: a repeated
    # sample integrated as new reads as a contact); after a stall the gap in one-cycle steps
    # from the last sample (each observer is tuned, and stable, for one cycle)
    period = ts["period"]
    obs_dt = 0.0
    if sdt >= 0.0:
        obs_dt = sdt if sdt > 0.0 else dt
        sw, so, sh = h["snap_W"], h["snap_O"], ts["snap_h"]
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
    # 4. safety: here unless a pre-safety step is Python's (then its second call, section4)
    if quiet:
        _quiet_inputs(ts)
    elif ts["pre"]:
        return SAFETY
    ts["use_mon"] = False
    if section4(hot, rec, tick, dt, False) == BUS:
        return BUS
    if not quiet or ts["nf"] > 0 or sdt < 0.0:
        return CONTROL
    # 5-7 (HOLD at rest: no controller step; MOVE: the demo path and its feed-forward)
    kind = ts["kind"]
    if kind == OTHER:
        return CONTROL
    what = S_PATH | S_FF if kind == MOVE_PATH else 0
    section57(hot, rx, rec, t_loop, tick, what, ts["mode"], 0, 0, wake, comp)
    return DONE


def hot_record(parts: dict[str, dict[str, np.dtype]]) -> tuple[np.ndarray, dict[str, dict]]:
    """The tick's one hot record (1,), zeroed, allocated before its parts: ``parts`` maps a
    part ("group", "snap", ...) to its ``hot_fields`` (name -> a record's or an array's
    dtype); field ``part_name``. Returns the record and, per part, its fields as the arrays
    its constructor takes (``hot=``): a record (1,), an array of its shape (booleans stored
    as their bytes: numba has no boolean subarray fields). Every field starts on a 16-byte
    boundary: a part's record dtype is packed (alignment 1), and an unaligned array is
    another type to numba (a compile in the loop) and slower to numpy."""
    names, formats, offsets, at = [], [], [], 0
    for part, fields in parts.items():
        for name, dt in fields.items():
            if dt.subdtype is not None and dt.subdtype[0] == np.bool_:
                dt = np.dtype((np.uint8, dt.shape))
            at = -(-at // 16) * 16
            names.append(f"{part}_{name}")
            formats.append(dt)
            offsets.append(at)
            at += dt.itemsize
    size = -(-at // 16) * 16
    layout = {"names": names, "formats": formats, "offsets": offsets, "itemsize": size}
    hot = np.zeros(1, K.interned(np.dtype(layout)))
    # plain arrays on the record's bytes (a field view's np.void keeps allocating when its
    # fields are written: ~1 kB per thousand ticks in the drag test, tracemalloc)
    buf, at_ = hot.view(np.uint8), iter(offsets)
    views = {
        part: {
            name: np.ndarray((1,), dt, buf, next(at_))
            if dt.names
            else np.ndarray(dt.shape, dt.base, buf, next(at_))
            for name, dt in fields.items()
        }
        for part, fields in parts.items()
    }
    return hot, views


def _parts(t: Tick) -> list[tuple[str, Any, str]]:
    """(field of the hot record, owner, attribute) of every hot array the fused call reads."""
    g, snap, m, c, fr = t.group, t.snapshot, t.motion, t.collision, _learning(t)
    out = [("tick_state", t, "state"), ("group_si", g, "_si"), ("group_states", g, "states")]
    out += [("snap_W", snap, "_W"), ("snap_O", snap, "_O"), ("ff_W", t.feedforward, "_W")]
    out += [("lim_w", t.limits, "_w"), ("motion_state", m, "state")]
    if c is not None:
        out += [("coll_record", c.state, "record"), ("coll_bbuf", c.state, "bbuf")]
    if fr is not None:
        out.append(("learn_record", fr, "record"))
    return out


def _on(hot: np.ndarray, field: str, a: np.ndarray) -> bool:
    """``a`` is the field ``field`` of ``hot`` (its view, from the part's construction)."""
    return a.ctypes.data == hot[field].ctypes.data and a.nbytes == hot[field].nbytes


def _learning(t: Tick) -> Any:
    """The drag's friction learning the tick runs outside drag mode, or None."""
    if t._learn is not None and t.drag is not None:
        return t.drag.friction
    return None


def _path_ok(p: Any) -> bool:
    """``p`` is a demo path the fused call evaluates (its compiled form)."""
    return p is not None and p._use_kernel and p._eval is path_eval


#: what :meth:`FusedTick.args` reads that can change while the tick runs (:meth:`FusedTick.
#: stale` compares): objects by identity, numbers by value. The motion's path, the native
#: models' handles (a model change), the bus's codes, the collision monitor, the friction
#: learning on or off and its row, the bank, the process images, the tick record, the path's
#: workspace and ramp, the tool-force check and its limit, the stop categories (the friction
#: learning's constants are its own, set when it is built)
_INPUTS: tuple[Callable[[Tick], Any], ...] = (
    lambda t: t.motion.path,
    lambda t: t.snapshot._native.handle,
    lambda t: t.feedforward._native.handle,
    lambda t: t.bus.fault_min,
    lambda t: t.bus.op_enabled,
    lambda t: t.collision,
    _learning,
    lambda t: t.drag_row,
    lambda t: t._bank.args,
    lambda t: t.group._tx_bytes,
    lambda t: t.group._rx_bytes,
    lambda t: t._rec1,
    lambda t: None if t.motion.path is None else t.motion.path._k,
    lambda t: None if t.motion.path is None else t.motion.path.ramp,
    lambda t: None if t.collision is None else t.collision._tool,
    lambda t: None if t.collision is None else t.collision.tool_force,
    lambda t: t.stop.categories,
)
_N_INPUTS = len(_INPUTS)
_NUMBERS = (int, float, np.integer)


class FusedTick:
    """The fused call's arguments for one :class:`~hofto_hw.runtime.tick.Tick`: the hot record
    ``tick.hot`` its parts were built on (:func:`hot_record`; ``why`` says why not when ``ok``
    is False). Nothing is copied or rebound: a part whose array is not its field is refused."""

    def __init__(self, tick: Tick) -> None:
        self.tick = tick
        self.hot: np.ndarray = tick.hot
        self.why = self._check(tick)
        self.ok = not self.why
        self.path: Any = None
        self._seen: list[Any] = []  # what args() read of _INPUTS (stale() compares with it)
        self.kept = [(o, a, getattr(o, a)) for _, o, a in _parts(tick)] if self.ok else []
        if self.ok:
            try:
                self._warm()
            except Exception as exc:  # numba's TypingError/LoweringError, a cache problem
                self.ok = False
                self.why = f"compiling the fused tick failed ({type(exc).__name__})"

    def bound(self) -> bool:
        """The parts still hold the arrays they were built on (a part that replaced one, e.g. a
        snapshot rebuilt for a new model, is not what the fused call reads)."""
        for o, a, arr in self.kept:  # a loop, not all() over a generator: ~2x faster
            if getattr(o, a) is not arr:
                return False
        return True

    def _check(self, t: Tick) -> str:
        """'' when every part can be fused, else why not."""
        if not K.available():
            return "the fused tick needs numba (" + K.unavailable_reason() + ")"
        g = t.group
        if g._fast is None:
            return "the drive group runs its kernels as Python"
        snap = t.snapshot
        if snap.model is not t.feedforward.model:
            return "the snapshot and the feed-forward use different models"
        if snap._native is None:
            return "the snapshot does not run the native dynamics"
        bank = t._bank
        if not (bank._any and bank._only) or bank._kernel is not bank_update:
            return "an observer is not fused in the bank: " + ", ".join(bank.rest)
        if t.backend != "numba":
            return "the tick's kernels run as Python (backend python)"
        if not t.bus._use_kernel or not t.limits._use_kernel:
            return "the drive scan or the limit checks run their kernels as Python"
        c = t.collision
        if c is not None and not c._use_kernel:
            return "the collision monitor runs its kernels as Python"
        fr = _learning(t)
        if fr is not None and not fr._use_kernel:
            return "the friction learning runs its kernels as Python"
        ff = t.feedforward
        if ff._native is None or ff._id_native is not inverse_dynamics_native:
            return "the feed-forward does not run the native RNEA"
        if t.hot is None:
            return "its parts were not built on one hot record (runtime.compose.build)"
        names = t.hot.dtype.names
        off = [f for f, o, a in _parts(t) if f not in names or not _on(t.hot, f, getattr(o, a))]
        return "parts not built on the tick's hot record: " + ", ".join(off) if off else ""

    def args(self) -> tuple[Any, ...]:
        """The call's arguments before this tick's scalars, and the parts' constants into the
        tick's state (:attr:`path_ok`: the motion's path is the compiled one on the hot record).
        Called again only when :meth:`stale`: whatever it reads that can change goes into
        :data:`_INPUTS`."""
        t = self.tick
        g, m, st = t.group, t.motion, t.st
        st["fault_min"], st["op_enabled"] = t.bus.fault_min, t.bus.op_enabled
        st["snap_h"] = t.snapshot._native.handle  # type: ignore[union-attr]
        st["ff_h"] = t.feedforward._native.handle  # type: ignore[union-attr]
        c = t.collision
        st["has_coll"] = c is not None
        st["has_tool"] = c is not None and c._tool is not None
        st["tool_limit"] = c.tool_force if st["has_tool"] else 0.0  # type: ignore[union-attr]
        st["cats"] = t.stop.categories
        fr = _learning(t)
        st["has_learn"] = fr is not None
        if fr is not None:
            st["l_row"], st["l_vs"], st["l_tau"] = t.drag_row, fr.v_s, fr.tau
            st["l_min"], st["l_every"] = fr.min_speed, fr.every
        p = self.path = m.path
        self.path_ok = _path_ok(p) and self.hot_path(p)
        if self.path_ok:
            st["ramp"] = p.ramp
        self._seen = [get(t) for get in _INPUTS]
        return (self.hot, t._bank.args, g._tx_bytes, g._rx_bytes, t._rec1)

    def stale(self) -> bool:
        """:meth:`args` would answer differently now: one of :data:`_INPUTS` is another
        object or number than it read. Allocates nothing (an index, not an iterator: a drag
        tick asks on every tick)."""
        t, seen, i = self.tick, self._seen, 0
        while i < _N_INPUTS:
            now, was = _INPUTS[i](t), seen[i]
            if now is not was and not (isinstance(now, _NUMBERS) and now == was):
                return True
            i += 1
        return False

    def moves(self, m: Any) -> bool:
        """The motion ``m`` (JointMotion) follows the demo path the call evaluates (MOVE)."""
        return m.mode == MOVE and self.path_ok and m.path is self.path

    def hot_path(self, p: Any) -> bool:
        """The path's workspace is its field of the hot record (built on it)."""
        return _on(self.hot, "path_k", p._k)

    def _warm(self) -> None:
        """Compile the kernel (all of it) with a lost sample, which returns after the drive
        read, here on a copy of the hot record: no state of the tick is touched."""
        hot, obs, tx, rx, rec = self.args()
        # a lost sample (sdt -1) on a tick that is not quiet: the read into the copy's rows,
        # then SAFETY; the argument types the tick passes (Tick.step)
        fused_tick(hot.copy(), obs, tx, rx, rec, 0.0, 0.0, -1.0, 0, 0.0, 0.0, False)
        # section 4's own call on a copy whose drive states read "not expected enabled", no
        # fault: the checks on the copy's zero sample, the tick record's copy written
        copy = hot.copy()
        copy[0]["tick_state"]["expect"] = False
        section4(copy, rec.copy(), 0, 1e-3, False)
        # sections 5-7's own call (a tick that is not quiet) on a copy: every step but the
        # demo path (its workspace may be absent), the argument types the tick passes
        copy = hot.copy()
        section57(copy, rx.copy(), rec.copy(), 0.0, 0, S_FF | S_OFF, 0, 0, 0, 0.0, 0.0)
