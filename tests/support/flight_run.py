"""A small recorded run for the flight-log replay tests: the simulated ER3A-class arm, a
20 N·m push on joint 2 built up within 10 ms at tick ONSET, HOFTO and the momentum
observer online, the collision monitor on the momentum estimate, every tick pushed into a
FlightRecorder, a collision event at the detection tick (plus ``event_delay`` ticks, to
make a log whose recorded decision is NOT what the thresholds give).

The loop follows the conventions replay documents: t from integer ns, dt = t[k] - t[k-1],
observers reset on tick 0 and updated from tick 1.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from hofto_hw.config import load_config
from hofto_hw.config.collision import CollisionConfig
from hofto_hw.experiments.table2 import simulate
from hofto_hw.model import RobotModel
from hofto_hw.observers import make_observer
from hofto_hw.recording.attachments import run_attachments, run_metadata
from hofto_hw.recording.flight_file import LogSpec
from hofto_hw.recording.record import EVENT_DTYPE, new_record
from hofto_hw.recording.recorder import FlightRecorder
from hofto_hw.replay.thresholds import ObserverThresholds, ThresholdsFile, write_thresholds
from safety.collision import CollisionMonitor

CONFIG = Path(__file__).resolve().parents[2] / "configs" / "er3a.yaml"
ONSET = 800
OBSERVERS = ["hofto", "momentum"]
MONITOR = CollisionConfig(base=[5.0] * 6, debounce_time=0.002)


def recorded_run(folder: Path, *, event_delay: int = 0, duration: float = 1.2) -> dict:
    """Record the run into folder/run.mcap; returns what the loop saw and decided."""
    cfg = load_config(CONFIG)
    model = RobotModel.from_config(cfg.robot)
    s = simulate(cfg, model, duration=duration)
    n_ticks = s.t.shape[0]
    tau = s.tau.copy()
    ramp = np.clip((np.arange(n_ticks) - ONSET) / 10.0, 0.0, 1.0)
    tau[:, 1] -= 20.0 * ramp  # the motor works against the push: the estimate sees +20 N·m
    t = (np.arange(n_ticks, dtype=np.int64) * 1_000_000) * 1e-9
    th_path = folder / "thresholds.yaml"
    write_thresholds(
        th_path,
        ThresholdsFile(
            robot=cfg.robot.name,
            observers={
                "momentum": ObserverThresholds(observer=cfg.observers["momentum"], monitor=MONITOR)
            },
        ),
    )
    observers = [make_observer(cfg.observers[name], model) for name in OBSERVERS]
    # the observers' implementation, as `hofto-hw run` records it: the replay runs the same
    metadata = {**run_metadata(CONFIG, cfg, "momentum"), "observer_backend": observers[0].backend}
    spec = LogSpec(
        folder / "run.mcap",
        list(cfg.robot.joints),
        OBSERVERS,
        attachments=run_attachments(CONFIG, cfg, thresholds_path=th_path),
        metadata=metadata,
        event_kinds={1: "collision"},
    )
    monitor = CollisionMonitor(MONITOR)
    rec = FlightRecorder(spec).start()
    tick, ev = new_record(rec.tick_dtype), new_record(EVENT_DTYPE)
    tau_ext = np.zeros((n_ticks, len(OBSERVERS), 6))
    detected_at = None
    for k in range(n_ticks):
        q, qd = s.q[k], s.qd[k]
        if k == 0:
            for o in observers:
                o.reset(q, qd)
            monitor.reset(qd)
        else:
            dt = t[k] - t[k - 1]
            for i, o in enumerate(observers):
                tau_ext[k, i] = o.update(q, qd, tau[k], dt)
            if monitor.update(tau_ext[k, 1], qd, dt) and detected_at is None:
                detected_at = k
        tick["t"], tick["tick"] = t[k], k
        tick["q"], tick["qd"], tick["tau"], tick["q_cmd"] = q, qd, tau[k], s.q_des[k]
        tick["tau_ext"] = tau_ext[k]
        tick["wrench"] = np.nan
        rec.push_tick(tick)
        if detected_at is not None and k == detected_at + event_delay:
            joint = int(np.flatnonzero(monitor.joints)[0]) if monitor.joints.any() else 1
            ev["t"], ev["tick"], ev["kind"], ev["joint"], ev["category"] = t[k], k, 1, joint, 1
            rec.push_event(ev)
    health = rec.close()
    assert health.dropped == 0 and health.write_errors == 0
    return {
        "path": spec.path,
        "detected_at": detected_at,
        "t": t,
        "q": s.q,
        "qd": s.qd,
        "tau": tau,
        "tau_ext": tau_ext,
    }
