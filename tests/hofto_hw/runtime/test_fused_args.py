"""The fused call's arguments (FusedTick.args) are rebuilt when something they are made of
changed and only then: a drag tick (never quiet) does not rebuild them; a model change (new
native handles: the old ones are freed), a changed bus code and a new path do."""

from __future__ import annotations

import tracemalloc
from typing import Any

import pytest

from hofto_hw import jit
from hofto_hw.config.models import SystemConfig
from hofto_hw.config.runtime import ScriptedDragConfig
from hofto_hw.control.joint_motion import DRAG, MOVE
from hofto_hw.model.payload import Payload, apply_payload
from hofto_hw.runtime.compose import build
from hofto_hw.runtime.drag_script import DragScript

pytestmark = pytest.mark.skipif(not jit.available(), reason=jit.unavailable_reason())


def _count_args(tick: Any) -> list[int]:
    """Wrap the tick's FusedTick.args to count its calls."""
    calls = [0]
    inner = tick._fz.args

    def args() -> tuple[Any, ...]:
        calls[0] += 1
        return inner()

    tick._fz.args = args
    return calls


def _handles_in_state(tick: Any) -> bool:
    st = tick.st
    return (
        int(st["snap_h"]) == tick.snapshot._native.handle
        and int(st["ff_h"]) == tick.feedforward._native.handle
    )


def test_drag_ticks_do_not_rebuild_the_arguments(cfg: SystemConfig) -> None:
    system = build(cfg, clock="sim", contact=False)
    try:
        tick = system.tick
        hand = ScriptedDragConfig(reset=0.01, mode=0.05, press=0.1, push_start=0.3)
        tick.script = DragScript(hand, system.bus.plant, system.rate_hz, enable=True)
        system.loop.run(max_ticks=100)
        assert tick.motion.mode == DRAG, tick.mode_result
        calls = _count_args(tick)
        before = tick._fz_args
        system.loop.run(max_ticks=500)
        assert tick.motion.mode == DRAG and tick.fused_ticks < 100
        assert calls[0] == 0 and tick._fz_args is before
        assert not tick._fz.stale()
    finally:
        system.close()


def test_a_model_change_a_bus_code_and_a_new_path_rebuild_them(cfg: SystemConfig) -> None:
    system = build(cfg, clock="sim", contact=False)
    try:
        tick = system.tick
        calls = _count_args(tick)
        system.loop.run(max_ticks=50)
        tick.mode_request = MOVE  # the demo path (the motion's own: the arguments hold it)
        system.loop.run(max_ticks=200)
        assert tick._fz.path is tick.motion.path and tick._fz.path_ok
        assert calls[0] == 0 and tick.fused_ticks > 150
        handles = (tick.snapshot._native.handle, tick.feedforward._native.handle)
        apply_payload(tick.feedforward.model, Payload(1.0, (0.0, 0.0, 0.05), (0.0,) * 6))
        system.loop.run(max_ticks=1)  # the native models follow: new handles in the state
        new = (tick.snapshot._native.handle, tick.feedforward._native.handle)
        assert calls[0] == 1 and new[0] != handles[0] and new[1] != handles[1]
        assert _handles_in_state(tick)
        system.loop.run(max_ticks=100)
        assert calls[0] == 1
        tick.bus.op_enabled += 1  # the drive code the call compares with
        assert tick._fz.stale()
        tick.bus.op_enabled -= 1
        assert not tick._fz.stale()
        cats, tick.stop.categories = tick.stop.categories, tick.stop.categories.copy()
        assert tick._fz.stale()  # section 4's compiled checks read the categories
        tick.stop.categories = cats
        path, tick.motion.path = tick.motion.path, None
        assert tick._fz.stale()
        tick.motion.path = path
        assert not tick._fz.stale()
    finally:
        system.close()


def test_every_input_of_the_arguments_makes_them_stale_and_asking_allocates_nothing(
    cfg: SystemConfig,
) -> None:
    """Each thing FusedTick.args reads that can change (fused._INPUTS) makes stale() answer
    True when it changes (an object replaced, a number changed) and False once it is back; an
    equal number in a new object is no change. stale() allocates nothing (a drag tick asks it
    on every tick)."""
    system = build(cfg, clock="sim", contact=False)
    try:
        tick = system.tick
        system.loop.run(max_ticks=20)
        fz = tick._fz
        assert not fz.stale()
        c = tick.collision
        assert c is not None
        changes: list[tuple[Any, str, Any]] = [
            (tick, "drag_row", tick.drag_row + 1),
            (tick, "collision", None),
            (tick, "_rec1", tick._rec1.copy()),
            (tick.group, "_rx_bytes", tick.group._rx_bytes.copy()),
            (tick.bus, "fault_min", tick.bus.fault_min + 1),
            (tick.snapshot._native, "handle", tick.snapshot._native.handle + 8),
            (c, "tool_force", 1.0 if c.tool_force is None else None),
            (c, "_tool", object()),
        ]
        for owner, name, value in changes:
            kept = getattr(owner, name)
            setattr(owner, name, value)
            assert fz.stale(), name
            setattr(owner, name, kept)
            assert not fz.stale(), name
        native = tick.snapshot._native
        native.handle = int(str(native.handle))  # the same number, another object
        assert not fz.stale()
        tracemalloc.start()
        try:
            for _ in range(10):
                fz.stale()
            tracemalloc.reset_peak()
            before = tracemalloc.get_traced_memory()[0]
            for _ in range(1000):
                fz.stale()
            now, peak = tracemalloc.get_traced_memory()
        finally:
            tracemalloc.stop()
        assert now - before <= 64 and peak - before <= 256, (now - before, peak - before)
    finally:
        system.close()


def _structured(args: Any) -> list[Any]:
    """Every structured array among the fused call's arguments (tuples walked), in order."""
    if isinstance(args, tuple):
        return [a for x in args for a in _structured(x)]
    return [args] if getattr(getattr(args, "dtype", None), "names", None) else []


def test_a_second_tick_in_one_process_passes_the_first_ones_dtype_objects(
    cfg: SystemConfig,
) -> None:
    """``hofto-hw run`` on a real bus builds the system once on the simulated arm (to compile)
    and then the one it runs: numba's dispatcher finds a structured array's compiled code at
    once only for the dtype object it saw first (an equal new one is compared field by field
    on every call, ~4 µs for the hot record). Every structured argument of the second tick's
    compiled calls is the first tick's dtype object."""
    first = build(cfg, clock="sim", contact=False)
    try:
        a = _structured((*first.tick._fz_args, first.tick._rec1))
    finally:
        first.close()
    second = build(cfg, clock="sim", contact=False)
    try:
        b = _structured((*second.tick._fz_args, second.tick._rec1))
        assert len(a) == len(b) >= 4  # the hot record, HOFTO's and momentum's, the tick record
        for x, y in zip(a, b, strict=True):
            assert y.dtype is x.dtype, y.dtype.names
    finally:
        second.close()
