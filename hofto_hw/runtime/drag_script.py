"""The scripted drag of ``hofto-hw run`` on the simulated arm (``run.drag``): after the
collision stop a script resets, requests drag mode, holds the enabling input, and a hand
pushes the tool of the *true* simulated arm; the figures come from the true plant state.

:class:`DragScript` is stepped by the tick at the start of every tick (compares the loop time
with fixed instants, sets the tick's request flags, copies the plant state into preallocated
rows: allocation-free). The hand is a :class:`HandForces` of the drag harness chained after the
plant's own external torques (simulation only: the plant is not the tick's hot path on a real
bus). :func:`drag_summary` computes the figures as ``drag_figures`` of
hofto_hw/experiments/drag_sim.py does, after the run.

With ``run.drag.replay`` (sim clock): the tick records the taught path from press to release
(a :class:`~hofto_hw.runtime.teach.Recording` handed over with the drag request, as ``mode
drag --record`` does), the release's stop is reset 0.2 s before ``replay``, and at ``replay``
the script asks for a plan: :func:`run_loop` ends that stretch of the loop, plans the replay
off the tick (:meth:`DragScript.start_replay`) and goes on, so the run stays deterministic.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from hofto_hw.config.runtime import ScriptedDragConfig
from hofto_hw.control.joint_motion import DRAG
from hofto_hw.experiments.drag_sim import (
    DragRun,
    HandForces,
    ToolPush,
    drag_figures,
    drift_mps,
    tool_motion,
)

_RESET, _MODE, _PRESS, _RELEASE, _REPLAY_RESET, _REPLAY, _DONE = range(7)
REPLAY_RESET_LEAD = 0.2  # [s] the release's stop is reset this long before the replay


class ChainedExternal:
    """The plant's external torques ``first`` plus ``second`` (both ``evaluate(t, q, qd,
    out)``)."""

    def __init__(self, first: Any, second: Any, n: int) -> None:
        self.first = first
        self.second = second
        self._tmp = np.zeros(n)
        self.components = getattr(first, "components", [])
        #: ``active(t)``: whether ``second`` can be non-zero at plant time t (None: always)
        self.active: Any = None

    def joint_space_only(self) -> bool:
        return False

    def evaluate(
        self, t: float, q: np.ndarray, qd: np.ndarray, out: np.ndarray | None = None
    ) -> np.ndarray:
        out = self.first.evaluate(t, q, qd, out=out)
        if self.active is None or self.active(t):  # the hand's kinematics only while it pushes
            self.second.evaluate(t, q, qd, out=self._tmp)
            out += self._tmp
        return out


class DragScript:
    """See the module docstring; built when the loop's t = 0 is the plant's now. ``rate_hz``:
    loop rate. Samples (true q, qd, commanded q) are kept from ``reset`` to 1 s after
    ``release``. ``enable``: False leaves the enabling input alone (tests). ``model``: the
    loop's model, needed for ``cfg.replay`` (None: no replay)."""

    def __init__(
        self,
        cfg: ScriptedDragConfig,
        plant: Any,
        rate_hz: float,
        enable: bool = True,
        model: Any = None,
    ) -> None:
        self.enable = enable
        self.cfg = cfg
        self.plant = plant
        n = plant.true_model.n
        self.push = ToolPush(
            tuple(cfg.force), plant.t + cfg.push_start, plant.t + cfg.push_end, cfg.ramp
        )
        self.hand = HandForces(plant.true_model)
        self.hand.pushes.append(self.push)
        chained = ChainedExternal(plant.external, self.hand, n)
        chained.active = self._pushing
        plant.external = chained
        self._times: tuple[float, ...] = (cfg.reset, cfg.mode, cfg.press, cfg.release)
        self.recording = None
        self.wants_plan = False  # set by the tick at cfg.replay; run_loop plans off the tick
        self.replay_result = ""
        if cfg.replay is not None and model is not None:
            from hofto_hw.runtime.teach import Recording

            cap = round((cfg.release - cfg.press + 0.5) * rate_hz)
            self.recording = Recording(None, False, model, cap)
            self._times += (cfg.replay - REPLAY_RESET_LEAD, cfg.replay)
        self.stage = _RESET
        self.mode_result = ""
        cap = round((cfg.release + 1.0 - cfg.reset) * rate_hz) + 2
        self.t = np.zeros(cap)
        self.q = np.zeros((cap, n))
        self.qd = np.zeros((cap, n))
        self.q_ref = np.zeros((cap, n))
        self.k = 0

    def _pushing(self, t: float) -> bool:
        return any(p.start < t < p.end for p in self.hand.pushes)

    def step(self, tick: Any) -> None:
        """Called by the tick first thing every tick (hot path)."""
        t = tick.t
        s = self.stage
        if s < len(self._times) and t >= self._times[s]:
            if s == _RESET or s == _REPLAY_RESET:
                tick.reset_requested = True
            elif s == _MODE:
                tick.record_request = self.recording
                tick.mode_request = DRAG
            elif s == _PRESS:
                tick.enable_input.pressed = self.enable
            elif s == _RELEASE:
                tick.enable_input.pressed = False
            else:
                self.wants_plan = True
            self.stage = s + 1
        if t >= self._times[0] and self.k < self.t.shape[0]:
            k = self.k
            self.t[k] = t
            np.copyto(self.q[k], self.plant.q)
            np.copyto(self.qd[k], self.plant.qd)
            np.copyto(self.q_ref[k], tick.motion.q)
            self.k = k + 1

    def start_replay(self, system: Any) -> str:
        """Plan the replay of the taught path from the held position and hand it to the tick
        (slow path, between two stretches of the loop); returns why not, or ""."""
        from hofto_hw.errors import UserError
        from hofto_hw.runtime import teach

        self.wants_plan = False
        tick, model = system.tick, system.model
        rec = self.recording
        if rec is None or rec.recorder.count < 10:
            self.replay_result = "no taught path recorded"
            return self.replay_result
        path = rec.recorder.path(model)
        limits = teach.motion_limits(system.cfg, model)
        try:
            pb = teach.plan_path(path, tick.motion.q.copy(), limits, 1.0 / system.rate_hz)
        except UserError as exc:  # the summary says why; the run goes on
            self.replay_result = f"not planned: {exc}"
            return self.replay_result
        tick.mode_result = ""
        tick.play_request = pb
        tick.mode_request = pb.mode
        return ""


def run_loop(system: Any, n_ticks: int | None, should_stop: Callable[[], bool]) -> None:
    """``system.loop.run(max_ticks=n_ticks, should_stop=...)`` (None: until ``should_stop``,
    which a scripted replay does not support); with a scripted replay, the
    loop stops where the script asks for a plan, plans off the tick and goes on (sim clock:
    the loop time does not advance meanwhile, so the run stays deterministic)."""
    script = system.drag_script
    loop = system.loop
    if script is None or script.recording is None or n_ticks is None:
        loop.run(max_ticks=n_ticks, should_stop=should_stop)
        return
    end = loop.ticks + n_ticks
    while loop.ticks < end:
        loop.run(max_ticks=end - loop.ticks, should_stop=lambda: should_stop() or script.wants_plan)
        if not script.wants_plan or should_stop():
            return
        script.start_replay(system)


def drag_summary(script: DragScript, damping: float, standstill: float) -> dict[str, Any]:
    """The ``drag.*`` summary keys (slow path, after the run); None where the run ended
    before the figure's window."""
    cfg, k = script.cfg, script.k
    keys = (
        "steady_speed_mps",
        "expected_speed_mps",
        "off_axis_mps",
        "rest_time_ms",
        "max_speed_mps",
    )
    out: dict[str, Any] = {key: None for key in (*keys, "drift_mps")}
    if k < 2 or script.t[k - 1] < cfg.push_end:
        return out
    run = DragRun(
        t=script.t[:k].copy(),
        q=script.q[:k],
        qd=script.qd[:k],
        q_ref=script.q_ref[:k],
        wrench=np.zeros((k, 6)),
        reason=np.zeros(k, dtype=np.int32),
        mode=np.zeros(k, dtype=np.int32),
        limited=np.zeros(k, dtype=np.int32),
        pressed=np.zeros(k, dtype=bool),
        hand_force=np.zeros((k, 3)),
    )
    run.tool, run.tool_v = tool_motion(script.plant.true_model, run.q, run.qd)
    # in loop time: the push window as the loop sees it
    push = ToolPush(tuple(cfg.force), cfg.push_start, cfg.push_end, cfg.ramp)
    fig = drag_figures(run, push, damping, standstill=standstill, settle=cfg.settle)
    for key in keys:
        out[key] = round(fig[key], 6 if key.endswith("mps") else 1)
    # drift: enabling held, no push yet
    w = (run.t >= cfg.press + 0.05) & (run.t < cfg.push_start)
    if w.sum() > 2:
        sub = DragRun(**{**run.__dict__})
        sub.t, sub.tool = run.t[w], run.tool[w]
        out["drift_mps"] = round(drift_mps(sub)["drift_mps"], 6)
    return out
