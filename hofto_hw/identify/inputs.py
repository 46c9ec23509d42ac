"""Command-line inputs shared by ``identify`` and ``validate``: recordings given as
``FILE`` or ``FILE@first:last`` (1-based inclusive rows), the column map found next to the
robot's files when not given, the config found from a parameters file's robot name.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hofto_hw.commands.args import parse_rows
from hofto_hw.errors import UserError
from hofto_hw.identify.data import (
    ColumnMap,
    Recording,
    condition,
    count_columns,
    load_column_map,
    load_recording,
    with_drive_gains,
)
from hofto_hw.identify.pipeline import Samples


@dataclass
class Conditioning:
    """Offline conditioning options: low-pass ``cutoff_hz`` [Hz], torque filtering,
    decimation factor, bad-row policy, trimming of standstill at the ends (off to keep the
    rest periods that identify held friction and static holds)."""

    cutoff_hz: float = 5.0
    filter_torque: bool = True
    decimation: int = 1
    drop_bad_rows: bool = False
    trim: bool = True


def split_spec(spec: str) -> tuple[Path, tuple[int, int] | None]:
    """``FILE@a:b`` -> (FILE, (a, b)); plain ``FILE`` -> (FILE, None)."""
    if "@" in spec:
        name, rows = spec.rsplit("@", 1)
        return Path(name), parse_rows(rows, f"{spec}")
    return Path(spec), None


def find_column_map(recording: Path, search: list[Path]) -> Path:
    """``columns_<k>.yaml`` for a CSV with k fields per row, from the ``search`` folders."""
    k = count_columns(recording)
    for folder in search:
        candidate = folder / f"columns_{k}.yaml"
        if candidate.is_file():
            return candidate
    raise UserError(
        f"{recording}: no column map given and no columns_{k}.yaml next to the robot's files; "
        "pass --columns FILE"
    )


def load_samples(
    specs: list[str],
    columns: Path | None,
    rows: tuple[int, int] | None,
    opts: Conditioning,
    search: list[Path],
    *,
    robot: str | None = None,
    gains: np.ndarray | None = None,
) -> list[tuple[Samples, Recording]]:
    """Load and condition every recording; (samples for the fit, the conditioned recording).

    With ``robot`` set, a column map written for another robot is refused (its ``robot``).
    ``gains`` (n,) [N·m/A]: a model's drive gains, replacing the current-to-torque gains of a
    map that reads current (``data.with_drive_gains``).
    """
    out = []
    for spec in specs:
        path, own_rows = split_spec(spec)
        cmap: ColumnMap | Path | None = columns
        if cmap is None and path.suffix.lower() != ".mcap":
            cmap = find_column_map(path, search)
        if cmap is not None:
            cmap = with_drive_gains(load_column_map(cmap, robot=robot), gains)
        rec = load_recording(
            path,
            cmap,
            rows=own_rows or rows,
            bad_rows="drop" if opts.drop_bad_rows else None,
        )
        rec = condition(
            rec,
            opts.cutoff_hz,
            filter_torque=opts.filter_torque,
            decimation=opts.decimation,
            trim=opts.trim,
        )
        assert rec.qdd is not None
        out.append((Samples(rec.q, rec.qd, rec.qdd, rec.tau, rec.source), rec))
    return out


def configured_gains(
    specs: list[str], columns: Path | None, search: list[Path], robot: str | None = None
) -> np.ndarray:
    """The current-to-torque gains (n,) [N·m/A] the column maps of ``specs`` read current
    with; UserError when a recording has no current column map or the maps differ."""
    found: np.ndarray | None = None
    for spec in specs:
        path, _ = split_spec(spec)
        if columns is None and path.suffix.lower() == ".mcap":
            raise UserError(f"{path}: an MCAP log holds joint torque, not current: no gain")
        where = columns if columns is not None else find_column_map(path, search)
        cmap = load_column_map(where, robot=robot)
        if cmap.current_to_torque is None:
            raise UserError(f"{where}: reads torque columns, not current: no gain to calibrate")
        g = np.asarray(cmap.current_to_torque, dtype=float)
        if found is not None and not np.array_equal(found, g):
            raise UserError(
                f"{where}: current_to_torque {g.tolist()} differs from the other recordings' "
                f"{found.tolist()}; calibrate recordings read with the same gains"
            )
        found = g
    assert found is not None
    return found
