"""The contact and collision thresholds the loop's monitor used, re-computed from logged records.

The loop does not log its thresholds (they would cost the tick); they are a function of what it
logs: ``safety.collision.CollisionLevels`` built from the run's config (the log's attachments),
stepped on the recorded estimates, velocities, commanded accelerations and observer intervals,
on the ticks the loop judged (``monitored``), as `hofto-hw replay` does to reproduce the run's
decision. One function (:func:`track_thresholds`) serves the run's figure (whole log) and the
flight recorder's writer process (``/safety/thresholds``, batch by batch, :class:`ThresholdTrack`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from hofto_hw.replay.flight_log import FlightLog

#: names of the levels, in the order of CollisionLevels.threshold's first axis
LEVELS_2 = ("contact", "collision")


def detector_levels(log: FlightLog) -> tuple[str, int, Any] | None:
    """(detector observer, its row, a fresh CollisionLevels) for a log of `hofto-hw run`
    (config attached, monitored ticks recorded); None when the run's detector is not the
    two-level monitor (older logs, thresholds-file monitors)."""
    from hofto_hw.replay.reproduce import make_detector, run_setup
    from safety.collision import CollisionLevels

    det = make_detector(log, run_setup(log))
    if not isinstance(det.monitor, CollisionLevels) or det.observer not in log.observers:
        return None
    return det.observer, log.observers.index(det.observer), det.monitor


def track_thresholds(
    mon: Any,
    row: int,
    est: np.ndarray,
    qd: np.ndarray,
    qdd_cmd: np.ndarray,
    h: np.ndarray,
    ticks: np.ndarray,
    monitored: np.ndarray,
    switches: list[tuple[int, float]] | None = None,
) -> np.ndarray:
    """Step ``mon`` (CollisionLevels, state carried between calls) on N ticks: estimates
    (N, k, n) [N·m], qd (N, n) [rad/s], commanded acceleration (N, n) [rad/s²], the observers'
    interval h (N,) [s], tick numbers (N,), judged flags (N,); ``switches``: the run's safety
    profile switches (tick, collision scale; reproduce.profile_switches), each taken after
    its tick as the loop did. Returns the thresholds (N, L, n) [N·m] of ``row``; NaN on ticks
    the loop did not judge."""
    out = np.full((len(h), mon.L, est.shape[2]), np.nan)
    pending = list(switches or [])
    for k in np.flatnonzero(monitored):
        while pending and pending[0][0] < ticks[k]:
            mon.scale_thresholds(pending.pop(0)[1])
        mon.step(est[k], qd[k], qdd_cmd[k], float(h[k]), int(ticks[k]))
        out[k] = mon.threshold[:, row, :]
    return out


def level_names(mon: Any) -> tuple[str, ...]:
    return LEVELS_2 if mon.L == 2 else ("collision",)


class ThresholdTrack:
    """The writer process's streaming version: built from what a LogSpec carries (attachments,
    metadata, joint names, observers); :meth:`update` takes drained tick records in order,
    :meth:`note_events` the drained safety events (a safety profile switch scales the
    thresholds from the tick after its own, as in the loop). LookupError when the run's
    detector is not the two-level monitor."""

    def __init__(
        self,
        attachments: dict[str, bytes],
        metadata: dict[str, str],
        joint_names: list[str],
        observers: list[str],
    ) -> None:
        n = len(joint_names)
        probe = FlightLog(
            path=Path("log"),
            t=np.zeros(0),
            ticks=np.zeros(0, dtype=np.int64),
            q=np.zeros((0, n)),
            qd=np.zeros((0, n)),
            tau=np.zeros((0, n)),
            joint_names=joint_names,
            observers=observers,
            metadata=metadata,
            attachments=attachments,
            monitored=np.zeros(0, dtype=np.uint8),
            qdd_cmd=np.zeros((0, n)),
        )
        found = detector_levels(probe)
        if found is None:
            raise LookupError("the run's detector is not the two-level collision monitor")
        self.observer, self.row, self.mon = found
        self.levels = level_names(self.mon)
        self.mon.reset()
        rate = float(metadata.get("rate_hz", "1000") or 1000.0)
        self._period = float(np.int64(round(1e9 / rate))) * 1e-9
        self._t_last: float | None = None
        #: profile switches not yet taken: (tick, collision scale), in tick order
        self.switches: list[tuple[int, float]] = []

    def note_events(self, events: np.ndarray) -> None:
        """Drained safety events (EVENT_DTYPE records): keep the profile switches. The writer
        drains the tick ring before the event ring, so a switch after tick k is here before
        (or with) the batch holding tick k + 1."""
        from safety.stop import EventKind

        for ev in events[events["kind"] == int(EventKind.PROFILE)]:
            self.switches.append((int(ev["tick"]), float(ev["value"])))
        self.switches.sort()

    def update(self, ticks: np.ndarray) -> np.ndarray:
        """Thresholds (N, L, n) [N·m] for tick records (N,) (see track_thresholds)."""
        t = ticks["t"]
        prev = t[0] - self._period if self._t_last is None else self._t_last
        # whole periods since the previous tick, as the loop hands dt to the tick (loop_dt)
        dt = np.maximum(1.0, np.round(np.diff(t, prepend=prev) / self._period)) * self._period
        h = np.where(ticks["sample_dt"] > 0.0, ticks["sample_dt"], dt)
        self._t_last = float(t[-1])
        return track_thresholds(
            self.mon, self.row, ticks["tau_ext"], ticks["qd"], ticks["qdd_cmd"], h,
            ticks["tick"], ticks["monitored"], self.switches,
        )  # fmt: skip
