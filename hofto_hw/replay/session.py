"""One replay as the commands run it: recording + setup + observer + thresholds -> report."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from hofto_hw.config.models import ObserverConfig
from hofto_hw.errors import ConfigError, UserError
from hofto_hw.identify.data import (
    BadRows,
    Recording,
    load_column_map,
    load_recording,
    with_drive_gains,
)
from hofto_hw.jit import Backend
from hofto_hw.observers import Observer, make_observer
from hofto_hw.observers.stability import check_observer
from hofto_hw.replay.episodes import Episode, find_episodes
from hofto_hw.replay.runner import Progress, ReplayResult, replay
from hofto_hw.replay.setup import Setup, default_columns
from hofto_hw.replay.thresholds import ThresholdsFile
from safety.collision import CollisionMonitor


@dataclass
class Report:
    """A finished replay: the result, its episodes and per-joint statistics."""

    result: ReplayResult
    episodes: list[Episode]
    calibrated: bool

    def stats(self) -> list[dict[str, float]]:
        """Per joint: mean, std, rms, max |.| of tau_ext_hat [N·m] (and peak ratio)."""
        e = self.result.tau_ext
        out = []
        for j in range(e.shape[1]):
            row = {
                "joint": j + 1,
                "mean": float(np.mean(e[:, j])),
                "std": float(np.std(e[:, j])),
                "rms": float(np.sqrt(np.mean(e[:, j] ** 2))),
                "max_abs": float(np.max(np.abs(e[:, j]))),
            }
            if self.result.threshold is not None:
                row["max_ratio"] = float(np.max(np.abs(e[:, j]) / self.result.threshold[:, j]))
            out.append(row)
        return out

    def as_dict(self) -> dict[str, Any]:
        """Plain types for --json."""
        rec = self.result.recording
        return {
            "file": rec.source,
            "observer": self.result.observer,
            "samples": rec.n_samples,
            "duration": rec.duration,
            "thresholds": self.calibrated,
            "episodes": [ep.as_dict() for ep in self.episodes],
            "joints": self.stats(),
            "notes": rec.notes,
        }


def load_for_replay(
    setup: Setup,
    path: Path,
    columns: Path | None,
    rows: tuple[int, int] | None = None,
    bad_rows: BadRows | None = None,
    progress: Callable[[str], Progress | None] | None = None,
) -> Recording:
    """The recording, with the robot's default column map when none is given (a map for
    another robot is refused). Replay needs no ``extra`` columns: they are not read."""
    cmap_path = columns if columns is not None else default_columns(setup, path)
    cmap = None
    if cmap_path is not None:  # current read with the model's calibrated gains, if it has them
        cmap = with_drive_gains(
            load_column_map(cmap_path, setup.config.robot.name), setup.parameters.drive_gains
        )
    rec = load_recording(
        path,
        cmap,
        rows=rows,
        bad_rows=bad_rows,
        keep_extra=False,
        progress=None if progress is None else progress("reading"),
    )
    if rec.n_joints != setup.model.n:
        raise UserError(
            f"{path}: {rec.n_joints} joints, robot {setup.config.robot.name} has {setup.model.n}"
        )
    return rec


def recording_rate(rec: Recording) -> float:
    """The recording's sampling rate [Hz]: 1 / median sample interval."""
    dt = rec.dt()
    step = float(np.median(dt)) if dt.size else 0.0
    if not (step > 0.0 and np.isfinite(step)):
        raise ConfigError(f"{rec.source}: cannot tell the sampling rate (median interval {step})")
    return 1.0 / step


def observer_for(
    name: str, cfg: ObserverConfig, setup: Setup, rec: Recording, backend: Backend = "auto"
) -> Observer:
    """Observer ``name`` built from ``cfg`` on ``backend``, refused (ConfigError) if its gains
    are unstable at the recording's rate."""
    rate = recording_rate(rec)
    try:
        check_observer(name, cfg, setup.model, rate)
    except ConfigError as exc:
        raise ConfigError(f"{rec.source} ({rate:.4g} Hz): {exc}") from None
    return make_observer(cfg, setup.model, backend=backend)


def run_replay(
    setup: Setup,
    rec: Recording,
    observer_name: str,
    thresholds: ThresholdsFile | None,
    merge_gap: float = 0.5,
    progress: Callable[[str], Progress | None] | None = None,
    backend: Backend = "auto",
) -> Report:
    """Replay ``observer_name`` (on ``backend``) over ``rec``; with thresholds also detect
    episodes."""
    from hofto_hw.replay.setup import observer_config

    obs_cfg = observer_config(observer_name, setup, thresholds)
    observer = observer_for(observer_name, obs_cfg, setup, rec, backend)
    monitor = None
    if thresholds is not None and observer_name in thresholds.observers:
        monitor = CollisionMonitor(thresholds.observers[observer_name].monitor)
    result = replay(rec, observer, monitor, progress)
    result.observer = observer_name
    episodes: list[Episode] = []
    if result.joints is not None and result.threshold is not None:
        episodes = find_episodes(
            rec.t, result.joints, result.tau_ext, result.threshold, rec.rows, merge_gap
        )
    return Report(result, episodes, monitor is not None)
