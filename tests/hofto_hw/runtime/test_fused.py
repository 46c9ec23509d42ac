"""The tick as built (the compiled call, hofto_hw/runtime/fused.py: sections 1-3 on every
tick, the rest on quiet ticks) against the Python reference (tests/support/reference_tick.py:
every stage on every tick), tick by tick: two identical systems through moves, holds, a
collision and its stop, a reset, drag, lost frames, stalls, a drive fault, a NaN measurement,
mode changes and model changes. Every tick record, every estimate and the state every part
keeps must be the same bit for bit, the compiled call must have run on every tick and
finished most, and no rare-event handler may have had work on a tick it finished."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from drivers.cia402 import kernels as drive_kernels
from hofto_hw import jit
from hofto_hw.config.loader import load_config
from hofto_hw.control.joint_motion import HOLD, MOVE
from hofto_hw.errors import ConfigError
from hofto_hw.model.payload import Payload, apply_payload
from hofto_hw.runtime import tick_events
from hofto_hw.runtime.compose import build
from hofto_hw.runtime.fused import DONE, FusedTick, fused_tick
from hofto_hw.runtime.tick import Tick
from safety.stop import Fault
from tests.support.reference_tick import ReferenceTick, use_reference

#: the tool force's limit [N]: over the move's own (17.75 N at most), under the obstacle's push
#: the tick before the monitor's collision (18.16 N at tick 3004): the tool force reports it
TOOL_FORCE = 18.0
CONFIG = Path(__file__).resolve().parents[3] / "configs" / "er3a.yaml"

pytestmark = pytest.mark.skipif(not jit.available(), reason=jit.unavailable_reason())


def _arrays(obj: Any) -> list[bytes]:
    """The bytes of every numpy array an object holds (its state, sorted by name)."""
    return [v.tobytes() for _, v in sorted(vars(obj).items()) if isinstance(v, np.ndarray)]


def _state(system: Any) -> list[Any]:
    """Everything the tick's parts keep from one tick to the next, and what they sent."""
    t, g = system.tick, system.group
    out: list[Any] = [
        t.tick_rec.tobytes(),
        t.tau_ext.tobytes(),
        t.tau_ff.tobytes(),
        t.q_sent.tobytes(),
        t._prev.tobytes(),
        g._rx_bytes.tobytes(),
        g._si.tobytes(),
        t.limits._w.tobytes(),
        t.snapshot._O.tobytes(),
        t.snapshot._W.tobytes(),
        t.feedforward._W.tobytes(),
        *_arrays(t.motion),
        tuple(t.st[f] for f in ("t_cmd", "sample_dt", "since_fresh", "monitored")),
        (t.bus.streak, t.bus.lost_total),
        (t.motion.version, t._ff_version, t.motion.mode, t.expect_enabled, t.enabling),
        (t.stop.latched, t.stop.category, t.stop.events.count, t.snapshot.finite),
        (t.n_stops, t.reset_result, t.mode_result, t.overruns, t.overrun_streak),
        t.stop.events.kind.tobytes() + t.stop.events.value.tobytes(),
    ]
    for obs in t.observers:
        out += _arrays(obs)
        core = getattr(obs, "core", None)
        if core is not None:
            out += _arrays(core)
    if t.collision is not None:
        s = t.collision.state
        out += [s.fbuf.tobytes(), s.bbuf.tobytes(), s.first_tick.tobytes()]
        out.append((t.collision.tool_force_value, t.collision._was_contact))
    if t.drag is not None and t.drag.friction is not None:
        out += _arrays(t.drag.friction)
    return out


def _pair(contact: bool, tool_force: float | None = None) -> tuple[Any, Any]:
    cfg = load_config(CONFIG)
    cfg.safety.collision.tool_force = tool_force
    fused, reference = (
        build(cfg, clock="sim", contact=contact),
        build(cfg, clock="sim", contact=contact),
    )
    use_reference(reference)
    assert isinstance(fused.tick._fz, FusedTick) and type(fused.tick) is Tick
    return fused, reference


#: what happens on a tick, besides the stages: a stop's report and note (safety latches)
_EVENTS = ("report", "note")


def _rare_handlers(reference: Any, busy: set[int]) -> None:
    """Every rare-event handler of the reference's tick (the methods of
    hofto_hw.runtime.tick_events.TickEvents, whichever a maintainer adds there) and its stop
    controller's report/note, wrapped to add the tick number to ``busy`` when called."""
    t = reference.tick
    names = [n for n, v in vars(tick_events.TickEvents).items() if callable(v)]
    names = [n for n in names if not n.startswith("__") and n != "_refresh"]
    assert "_reset" in names and "_change_mode" in names and "_measure_stop" in names
    for owner, attrs in ((t, names), (t.stop, _EVENTS)):
        for name in attrs:
            original = getattr(owner, name)

            def wrapped(*args: Any, _f: Any = original, **kw: Any) -> Any:
                busy.add(t.tick)
                return _f(*args, **kw)

            setattr(owner, name, wrapped)


def _compare(fused: Any, reference: Any, k: int) -> None:
    a, b = _state(fused), _state(reference)
    for i, (x, y) in enumerate(zip(a, b, strict=True)):
        assert x == y, f"tick {k}: state item {i} differs"


def _lockstep(
    fused: Any,
    reference: Any,
    ticks: int,
    event: Any,
    late: frozenset[int] = frozenset(),
    rare: bool = True,
) -> dict[int, int]:
    """Both systems through ``ticks`` ticks (``late``: ticks that report a missed deadline at
    a regular dt); the stage each compiled call of the fused system answered, by tick. A tick
    the compiled call finished (DONE) on which the reference called a rare-event handler
    fails: a rare state the quiet decision (Tick.busy) missed (``rare``: the scenario has
    some)."""
    period = 1.0 / fused.rate_hz
    now = 0.0
    stages: dict[int, int] = {}
    busy: set[int] = set()
    _rare_handlers(reference, busy)
    assert type(reference.tick) is ReferenceTick
    call = fused.tick._fz_call

    def counted(*args: Any) -> int:
        stages[fused.tick.tick] = stage = call(*args)
        return stage

    fused.tick._fz_call = counted
    # sections 5-7 have one sequencing: the quiet tick's call, else section57 after the
    # Python stages; never the parts' Python feed-forward or command
    late57: set[int] = set()
    call57 = fused.tick._s57_call

    def counted57(*args: Any) -> None:
        late57.add(fused.tick.tick)
        call57(*args)

    def python_step(*args: Any, **kw: Any) -> None:
        raise AssertionError(f"tick {fused.tick.tick}: a section 5-7 step ran as Python")

    fused.tick._s57_call = counted57
    fused.tick.feedforward.inverse_dynamics = python_step
    fused.group.command_position = python_step
    for k in range(1, ticks + 1):
        dt = event(k, period)
        now += dt
        missed = round(dt / period) - 1 + (k in late)  # a stall's missed deadlines
        for s in (fused, reference):
            s.tick.step(now, dt, 1.5, missed, 2.5)
        _compare(fused, reference, k)
        assert not (k in busy and stages.get(k) == DONE), f"tick {k}: taken as quiet"
    assert bool(busy) == rare, sorted(busy)[:10]
    assert late57 == {k for k, stage in stages.items() if stage != DONE}
    return stages


def test_the_run_scenario_is_the_reference_tick_by_tick() -> None:
    """The main job's world (the path, the collision at 3 s and its stop, the reset, drag
    with the hand's push, the taught path's release), with stalls and lost frames."""
    fused, reference = _pair(contact=True)
    try:

        def event(k: int, period: float) -> float:
            if k == 50:
                for s in (fused, reference):
                    s.tick.mode_request = MOVE
            if k in (40, 2500, 6200):
                for s in (fused, reference):
                    s.bus.drop_cycles(1 + k % 2)  # lost frames: stale samples, then a gap
            return period * 2 if k in (30, 2700, 6300) else period  # stalls

        stages = _lockstep(fused, reference, 6500, event)
        t = fused.tick
        # sections 1-3 compiled on every tick (the stop, the drag, the stalls and lost frames)
        assert len(stages) == 6500, len(stages)
        assert t.n_stops >= 1, "the collision did not stop the arm"
        assert t.drag is not None and t.drag.friction is not None
        assert t.drag.friction.seconds > 0.0  # the friction learning ran (fused)
        # the stop and the drag (3-6 s) run the reference; the move and the holds the fused call
        assert t.fused_ticks > 2800, t.fused_ticks
        assert reference.tick.fused_ticks == 0
    finally:
        fused.close()
        reference.close()


def test_faults_resets_and_mode_changes_are_the_reference_tick_by_tick() -> None:
    """A drive fault and its reset, a NaN measurement and its reset, a stop request, holds
    and moves, lost frames and stalls, a payload and a parameter change: the fused ticks hand
    each over to the reference."""
    fused, reference = _pair(contact=False)
    systems = (fused, reference)
    rad_row = drive_kernels.RAD_PER_COUNT
    saved = fused.group._si[rad_row, 3]

    def event(k: int, period: float) -> float:
        for s in systems:
            t = s.tick
            if k in (20, 1500, 2600, 3300):
                t.mode_request = MOVE
            elif k in (1200, 2300, 3000):
                t.mode_request = HOLD
            elif k == 1400:
                s.bus.inject_fault(2, "over_temperature")
            elif k in (1460, 2000, 2900):
                t.reset_requested = True
            elif k == 1900:
                s.group._si[rad_row, 3] = np.nan  # the measurement turns NaN for a tick
            elif k == 1901:
                s.group._si[rad_row, 3] = saved
            elif k == 2800:
                t.stop_requested = True
            elif k == 2801:
                t.stop_requested = False
            elif k in (700, 2450):
                s.bus.drop_cycles(2)
            elif k == 1300:  # a tool picked up at the hold (new C++ models: new handles)
                load = Payload(1.0, (0.0, 0.0, 0.05), (0.0,) * 6)
                apply_payload(s.bus.plant.true_model, load)
                apply_payload(t.feedforward.model, load)
            elif k == 2700:  # a parameter change while moving
                for model in (s.bus.plant.true_model, t.feedforward.model):
                    model.rotor_inertia = model.rotor_inertia * 1.05
        return period * 3 if k in (900, 1700) else period

    try:
        # late ticks, stopped (the reference counts them) and moving (DONE: counted after the
        # call): the overruns and the streak are in the compared state
        late = frozenset(range(1201, 1221)) | frozenset(range(2301, 2311)) | {600, 601}
        stages = _lockstep(fused, reference, 4500, event, late)
        t = fused.tick
        assert DONE in {stages[k] for k in late} and t.overruns >= 34, t.overruns
        # every tick, those whose model changed included (its arguments refreshed first)
        assert len(stages) == 4500, len(stages)
        assert t.n_stops >= 3, t.n_stops  # the drive fault, the NaN, the stop request
        assert t.stop.latched == 0, t.stop.latched_names()
        # the stops, the resets' settling, the ramps to standstill and a move whose model
        # changed run the reference; the rest the fused call
        assert t.fused_ticks > 2800, t.fused_ticks
        assert reference.tick.fused_ticks == 0
    finally:
        fused.close()
        reference.close()


def test_the_tool_force_check_is_the_reference_tick_by_tick() -> None:
    """The collision monitor's tool-force limit configured (no compiled form: a Python step
    before section 4 on every tick, then section 4's own compiled call): the move into the
    main job's obstacle, tick by tick, the tool force's COLLISION report included."""
    fused, reference = _pair(contact=True, tool_force=TOOL_FORCE)
    try:

        def event(k: int, period: float) -> float:
            if k == 50:
                for s in (fused, reference):
                    s.tick.mode_request = MOVE
            return period

        _lockstep(fused, reference, 3400, event)
        t = fused.tick
        assert t.fused_ticks == 0  # never quiet: the tool force is Python's every tick
        assert t.collision.tool_force_value > 0.0
        ev = t.stop.events
        tool = [i for i in range(ev.count) if ev.kind[i] == Fault.COLLISION and ev.joint[i] < 0]
        assert tool, "the tool force did not report the contact"
    finally:
        fused.close()
        reference.close()


def test_a_stall_while_holding_is_compiled_to_the_end() -> None:
    """Stalls of two and three cycles (missed deadlines, the overrun streak short of its
    fault) while holding: the compiled call integrates the gap in sub-steps and finishes the
    tick, bit for bit the reference's; the missed deadlines are counted. (Not while moving
    here: the simulated arm moves one cycle per exchange, so a stall's gap reads as a
    contact.)"""
    fused, reference = _pair(contact=False)

    def event(k: int, period: float) -> float:
        return {400: 2 * period, 600: 3 * period}.get(k, period)

    try:
        stages = _lockstep(fused, reference, 700, event, rare=False)
        assert stages[400] == DONE and stages[600] == DONE, (stages[400], stages[600])
        assert fused.tick.overruns == 3 and fused.tick.stop.latched == 0
    finally:
        fused.close()
        reference.close()


def test_a_quiet_tick_is_one_fused_call() -> None:
    """Holding and moving, every tick after the settling is finished by the fused call, with
    nothing compiled while running."""
    cfg = load_config(CONFIG)
    system = build(cfg, clock="sim", contact=False)
    try:
        t = system.tick
        # the compiled call on the parts' own arrays, compiled when the tick was built
        assert isinstance(t._fz, FusedTick) and t._fz_call is fused_tick
        compiled = len(fused_tick.signatures)
        stages: list[int] = []
        call = t._fz_call

        def counted(*args: Any) -> int:
            stages.append(call(*args))
            return stages[-1]

        t._fz_call = counted
        t.mode_request = MOVE
        system.loop.run(max_ticks=1500)
        assert len(stages) == 1500 and stages[-300:] == [DONE] * 300
        assert t.fused_ticks == stages.count(DONE)
        assert len(fused_tick.signatures) == compiled  # nothing compiled while running
    finally:
        system.close()


def test_a_part_the_compiled_call_cannot_run_is_refused_in_one_line() -> None:
    """No silent Python path: a tick whose parts the compiled call cannot take (here the
    drive group on its interpreter path) is refused when built, naming why."""
    cfg = load_config(CONFIG)
    system = build(cfg, clock="sim", contact=False)
    try:
        t = system.tick
        t.group._fast = None
        with pytest.raises(ConfigError, match=r"^the tick cannot run compiled: the drive group"):
            Tick(
                t.group, t.observers, t.snapshot, t.stop, t.limits, t.bus, t.collision,
                t.motion, t.feedforward, t.sink, backend="numba",
            )  # fmt: skip
    finally:
        system.close()


def test_the_parts_are_built_on_the_hot_record_and_a_part_off_it_is_refused() -> None:
    """compose.build allocates the hot record first and builds every part on its fields: the
    arrays the compiled call reads are the parts' own (a drive read lands in the record, no
    copy). A tick given a part whose array is not its field, or no record at all, is
    refused in one line naming why (nothing is copied or rebound to make it fit)."""
    import copy

    from hofto_hw.runtime.fused import _parts

    cfg = load_config(CONFIG)
    system = build(cfg, clock="sim", contact=False)
    try:
        t = system.tick
        hot = t.hot
        for field, owner, attr in _parts(t):
            a = getattr(owner, attr)
            assert a.ctypes.data == hot[field].ctypes.data, field
            assert np.shares_memory(a, hot), field
        assert t.motion.path is not None and t._fz.hot_path(t.motion.path)
        t.group.cycle()
        assert np.array_equal(hot["group_si"][0][:3], t.group.sample)
        assert hot["group_si"][0, 0].ctypes.data == t.group.q.ctypes.data
        parts = (t.group, t.observers, t.snapshot, t.stop)
        rest = (t.bus, t.collision, t.motion, t.feedforward, t.sink)
        with pytest.raises(ConfigError, match=r"^the tick cannot run compiled: its parts were not"):
            Tick(*parts, t.limits, *rest, backend="numba")
        off = copy.copy(t.limits)
        off._w = t.limits._w.copy()  # same numbers, its own memory
        with pytest.raises(ConfigError, match=r"hot record: lim_w$"):
            Tick(*parts, off, *rest, backend="numba", hot=hot)
    finally:
        system.close()
