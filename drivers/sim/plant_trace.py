"""The true arm's state at every plant step for a while: what an emulator's ``trace`` /
``trace_read`` control requests answer (a test process starved of CPU would sample it too
rarely). Used by the CANopen emulator; the EtherCAT one keeps its own copy for now."""

from __future__ import annotations

import math
from typing import Any


class PlantTrace:
    """(t, q, qd) of ``plant`` at every :meth:`sample` until a plant time set by
    :meth:`start`."""

    def __init__(self, plant: Any) -> None:
        self.plant = plant
        self.samples: list[tuple[float, list[float], list[float]]] = []
        self.until = -math.inf

    def start(self, seconds: float) -> None:
        """Record from now for ``seconds`` (0, 60] of plant time."""
        if not (math.isfinite(seconds) and 0.0 < seconds <= 60.0):
            raise ValueError(f"trace seconds {seconds} not in (0, 60]")
        self.samples = []
        self.until = self.plant.t + seconds

    def sample(self) -> None:
        """After a plant step: keep its state while the trace runs."""
        p = self.plant
        if p.t <= self.until:
            self.samples.append((p.t, p.q.tolist(), p.qd.tolist()))

    def read(self) -> dict[str, Any]:
        """The trace so far: t, q, qd lists, ``done`` once its time is over."""
        t, q, qd = zip(*self.samples, strict=True) if self.samples else ((), (), ())
        return {"t": list(t), "q": list(q), "qd": list(qd), "done": self.plant.t > self.until}
