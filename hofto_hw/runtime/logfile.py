"""Interim run log: the in-memory sink's records saved as one .npz file after the run.

The MCAP flight recorder (branch ``recorder``) replaces this: it takes the same records from
the same sink interface while the loop runs. Never overwrites: the name carries time and pid.
"""

from __future__ import annotations

import json
import os
import time
from pathlib import Path
from typing import Any

import numpy as np

from hofto_hw.errors import UserError
from hofto_hw.recording.record import MemorySink


def save_memory_log(system: Any, folder: Path) -> Path | None:
    """Write ``system.sink`` (a MemorySink) to ``folder``/run-<time>-<pid>.npz; returns it."""
    sink = system.sink
    if not isinstance(sink, MemorySink):
        return None
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UserError(f"run.log_dir: cannot create {folder}: {exc.strerror}") from None
    path = folder / f"run-{time.strftime('%Y%m%d-%H%M%S')}-{os.getpid()}.npz"
    meta = {
        "observers": system.observer_names,
        "rate_hz": system.rate_hz,
        "robot": system.model.name,
    }
    with open(path, "xb") as fh:
        np.savez_compressed(
            fh,
            ticks=sink.last_ticks(),
            events=sink.last_events(),
            meta=np.frombuffer(json.dumps(meta).encode(), dtype=np.uint8),
        )
    return path
