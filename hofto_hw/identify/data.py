"""Recordings of joint data: reading (CSV through a column map, our own MCAP logs) and
offline conditioning (zero-phase low-pass, acceleration, standstill trimming, decimation).

A :class:`Recording` holds SI joint-side data: ``t`` (N,) [s], ``q`` (N, n) [rad],
``qd`` (N, n) [rad/s], ``tau`` (N, n) [N·m] and, after :func:`condition`, ``qdd`` (N, n)
[rad/s²]. Time stamps are kept as recorded: real loggers sample irregularly, and every
derivative here uses the actual ``t[k] - t[k-1]``.

Bad rows (wrong field count, text that is not a number, NaN/inf, values outside the column
map's plausibility limits, time that does not advance or jumps forward by more than
``max_time_step``) are handled by the ``bad_rows`` policy:

- ``refuse`` (default): raise :class:`~hofto_hw.errors.UserError` naming file, row and column;
- ``drop``: drop them, log one warning listing the rows and keep the same text in
  ``Recording.notes``; still refuse when more than ``MAX_DROP_FRACTION`` of the rows are bad.

Nothing is ever dropped silently. Rows are numbered from 1 as in a text editor.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray
from pydantic import Field, model_validator

from hofto_hw.config.base import FileModel
from hofto_hw.config.loader import read_model, require_regular
from hofto_hw.errors import ConfigError, UserError

log = logging.getLogger(__name__)

FloatArray = NDArray[np.float64]
BadRows = Literal["refuse", "drop"]

#: at least this many samples must remain after loading, trimming and decimation
MIN_SAMPLES = 20
#: ``drop`` refuses a file in which more than this fraction of the rows is bad
MAX_DROP_FRACTION = 0.05
#: absolute limit for any used numeric column when the column map gives none
DEFAULT_ABS_LIMIT = 1.0e6


# ------------------------------------------------------------------------------ recording


@dataclass
class Recording:
    """Joint data of one recording, SI at the joint side.

    Attributes:
        t: (N,) time stamps [s], strictly increasing, irregular spacing allowed.
        q: (N, n) joint positions [rad].
        qd: (N, n) joint velocities [rad/s].
        tau: (N, n) joint torques (motor torque through the gear) [N·m].
        source: file the data came from (used in every message about it).
        rows: (N,) 1-based row (CSV line or MCAP message number) of each sample.
        extra: named (N, k) arrays of further columns the column map asked to keep.
        qdd: (N, n) joint accelerations [rad/s²] once :func:`condition` computed them.
        notes: plain-text remarks about what was done to the data (dropped rows, trimming).
    """

    t: FloatArray
    q: FloatArray
    qd: FloatArray
    tau: FloatArray
    source: str
    rows: NDArray[np.int64]
    extra: dict[str, FloatArray] = field(default_factory=dict)
    qdd: FloatArray | None = None
    notes: list[str] = field(default_factory=list)

    @property
    def n_samples(self) -> int:
        """N, the number of samples."""
        return int(self.t.shape[0])

    @property
    def n_joints(self) -> int:
        """n, the number of joints."""
        return int(self.q.shape[1])

    @property
    def duration(self) -> float:
        """t[-1] - t[0] [s]."""
        return float(self.t[-1] - self.t[0]) if self.n_samples else 0.0

    def dt(self) -> FloatArray:
        """(N-1,) sample intervals t[k] - t[k-1] [s]."""
        return np.diff(self.t)

    def select(self, index: slice | NDArray[Any]) -> Recording:
        """A new recording with the samples ``index`` (a slice, index or boolean array)."""
        return replace(
            self,
            t=self.t[index],
            q=self.q[index],
            qd=self.qd[index],
            tau=self.tau[index],
            rows=self.rows[index],
            extra={k: v[index] for k, v in self.extra.items()},
            qdd=None if self.qdd is None else self.qdd[index],
            notes=list(self.notes),
        )


# ----------------------------------------------------------------------------- column map


class ColumnMap(FileModel):
    """Where each quantity sits in a CSV file (column numbers start at 1).

    Joint torque comes either from ``torque`` columns [N·m] or from ``current`` columns [A]
    times ``current_to_torque`` gains [N·m/A]. Columns not named are ignored.
    """

    name: str = Field("", description="layout name shown in messages")
    robot: str | None = Field(
        None, description="robot the map is written for (robot.name); None = any robot"
    )
    columns: int | None = Field(None, ge=1, description="fields per row; None = any")
    delimiter: str = ","
    header_rows: int = Field(0, ge=0, description="rows to skip at the top (headers)")
    time: int = Field(ge=1)
    time_scale: float = Field(1.0, gt=0.0, description="multiplies time to give seconds")
    q: list[int] = Field(min_length=1)
    qd: list[int] = Field(min_length=1)
    current: list[int] | None = None
    current_to_torque: list[float] | None = Field(None, description="gain per joint [N·m/A]")
    torque: list[int] | None = None
    extra: dict[str, list[int]] = Field(default_factory=dict)
    limits: dict[Literal["time", "q", "qd", "current", "torque", "extra"], float] = Field(
        default_factory=dict, description="absolute plausibility limit per kind of column"
    )
    max_time_step: float = Field(
        1.0, gt=0.0, description="a larger forward jump of time marks a row as corrupt [s]"
    )
    rows: tuple[int, int] | None = Field(None, description="1-based inclusive row range")
    bad_rows: BadRows = "refuse"

    @model_validator(mode="after")
    def _check(self) -> ColumnMap:
        n = len(self.q)
        if len(self.qd) != n:
            raise ValueError(f"qd has {len(self.qd)} columns, q has {n}")
        if (self.current is None) == (self.torque is None):
            raise ValueError("give exactly one of current (with current_to_torque) or torque")
        if self.current is not None:
            if len(self.current) != n:
                raise ValueError(f"current has {len(self.current)} columns, q has {n}")
            if self.current_to_torque is None or len(self.current_to_torque) != n:
                raise ValueError(f"current_to_torque needs {n} gains [N·m/A], one per joint")
        if self.torque is not None and len(self.torque) != n:
            raise ValueError(f"torque has {len(self.torque)} columns, q has {n}")
        used = self.used_columns()
        if min(used) < 1:
            raise ValueError("column numbers start at 1")
        if self.columns is not None and max(used) > self.columns:
            raise ValueError(f"column {max(used)} is beyond columns = {self.columns}")
        if self.rows is not None and not (1 <= self.rows[0] <= self.rows[1]):
            raise ValueError(
                f"rows = {list(self.rows)} must be [first, last] with 1 <= first <= last"
            )
        return self

    @property
    def n_joints(self) -> int:
        """Number of joints n the map describes."""
        return len(self.q)

    def used_columns(self) -> list[int]:
        """Every 1-based column the map reads."""
        cols = [self.time, *self.q, *self.qd, *(self.current or []), *(self.torque or [])]
        for c in self.extra.values():
            cols += c
        return cols


def with_drive_gains(cmap: ColumnMap, gains: Sequence[float] | np.ndarray | None) -> ColumnMap:
    """``cmap`` reading current with ``gains`` [N·m/A] (n,) instead of its own
    ``current_to_torque`` (a parameters file's calibrated ``drive_gains``); a map that reads
    torque, or ``gains`` None, is returned as it is."""
    if gains is None or cmap.current is None:
        return cmap
    values = [float(g) for g in np.asarray(gains, dtype=float).reshape(-1)]
    if len(values) != cmap.n_joints:
        raise ConfigError(
            f"{cmap.name}: the model's drive_gains has {len(values)} gains, the column map "
            f"reads {cmap.n_joints} currents"
        )
    return cmap.model_copy(update={"current_to_torque": values})


def load_column_map(path: str | Path | ColumnMap, robot: str | None = None) -> ColumnMap:
    """Read a column-map YAML file (a :class:`ColumnMap` passes through); errors name the
    file and the field. With ``robot``, a map written for another robot is refused."""
    if isinstance(path, ColumnMap):
        cmap, where = path, path.name
    else:
        cmap = read_model(path, "column map", ColumnMap)
        where = str(path)
        if not cmap.name:
            cmap.name = Path(path).name
    if robot is not None and cmap.robot is not None and cmap.robot != robot:
        raise ConfigError(
            f"{where}: robot: column map is for robot {cmap.robot!r}, the config is for "
            f"{robot!r}; pass the column map of this robot (--columns)"
        )
    return cmap


# ------------------------------------------------------------------------------- CSV input


def _ranges(rows: list[int]) -> str:
    """'2-10, 6107' from [2, 3, ..., 10, 6107]."""
    out: list[str] = []
    start = prev = rows[0]
    for r in [*rows[1:], None]:
        if r is not None and r == prev + 1:
            prev = r
            continue
        out.append(f"{start}" if start == prev else f"{start}-{prev}")
        if r is not None:
            start = prev = r
    return ", ".join(out)


def _parse_fields(
    lines: list[str], first_row: int, cmap: ColumnMap, source: str, used: list[int]
) -> tuple[FloatArray, dict[int, str]]:
    """Parse the ``used`` columns of ``lines`` into (R, C) floats; bad rows -> {row: reason}.

    Bad rows are left as NaN in the array and reported in the dict.
    """
    col_index = {c: i for i, c in enumerate(used)}
    out = np.full((len(lines), len(used)), np.nan)
    bad: dict[int, str] = {}
    expected = cmap.columns
    need = max(used)
    for k, line in enumerate(lines):
        row = first_row + k
        fields = line.split(cmap.delimiter)
        if expected is not None and len(fields) != expected:
            what = "empty row" if not line.strip() else f"{len(fields)} columns"
            bad[row] = f"{what}, expected {expected}"
            continue
        if len(fields) < need:
            bad[row] = f"{len(fields)} columns, the column map reads column {need}"
            continue
        for c in used:
            try:
                out[k, col_index[c]] = float(fields[c - 1])
            except ValueError:
                bad[row] = f"column {c}: not a number ({fields[c - 1].strip()[:20]!r})"
                break
    return out, bad


def _kind_columns(cmap: ColumnMap) -> list[tuple[str, list[int]]]:
    kinds: list[tuple[str, list[int]]] = [("time", [cmap.time]), ("q", cmap.q), ("qd", cmap.qd)]
    if cmap.current is not None:
        kinds.append(("current", cmap.current))
    if cmap.torque is not None:
        kinds.append(("torque", cmap.torque))
    for cols in cmap.extra.values():
        kinds.append(("extra", cols))
    return kinds


def _layout(cmap: ColumnMap) -> list[int]:
    """The used columns in the order the arrays are stored: time, q, qd, current/torque,
    extra (each column once), so that each quantity is a slice of the stored block."""
    return list(dict.fromkeys(cmap.used_columns()))


def _check_values(data: FloatArray, first_row: int, cmap: ColumnMap, bad: dict[int, str]) -> None:
    """Mark rows with NaN/inf or implausible values as bad (in place)."""
    col_index = {c: i for i, c in enumerate(_layout(cmap))}
    for kind, cols in _kind_columns(cmap):
        limit = cmap.limits.get(kind, DEFAULT_ABS_LIMIT)  # type: ignore[call-overload]
        if kind == "time":
            limit = cmap.limits.get("time", math.inf)
        for c in cols:
            x = data[:, col_index[c]]
            for k in np.flatnonzero(~np.isfinite(x) | (np.abs(x) > limit)):
                row = first_row + int(k)
                if row in bad:
                    continue
                v = x[k]
                if not np.isfinite(v):
                    bad[row] = f"column {c} ({kind}): {'NaN' if np.isnan(v) else 'infinite'}"
                else:
                    bad[row] = f"column {c} ({kind}): {v:.4g} exceeds the plausible {limit:g}"


def _check_time(t: FloatArray, first_row: int, max_step: float, bad: dict[int, str]) -> None:
    """Mark rows whose time does not advance, or jumps ahead by > max_step, as bad."""
    if not bad:
        step = np.diff(t)
        if np.all((step > 0.0) & (step <= max_step)):
            return  # the usual case, without a Python loop over millions of rows
    last: float | None = None
    for k in range(t.shape[0]):
        row = first_row + k
        if row in bad:
            continue
        tk = float(t[k])
        if last is not None:
            step_k = tk - last
            if step_k <= 0.0:
                bad[row] = f"column time: {tk:.6g} s does not advance past {last:.6g} s"
                continue
            if step_k > max_step:
                bad[row] = (
                    f"column time: jumps {step_k:.4g} s ahead (more than max_time_step "
                    f"{max_step:g} s)"
                )
                continue
        last = tk


#: bytes read from a CSV file at a time (memory stays O(chunk) besides the result arrays)
CHUNK_BYTES = 4 << 20


def _decode(block: bytes, src: str, offset: int) -> list[str]:
    """Lines of one block of a CSV file; a binary or non-UTF-8 file gives one clear error."""
    nul = block.find(b"\x00")
    if nul >= 0:
        raise UserError(f"{src}: byte {offset + nul}: NUL byte: a binary file, not a CSV recording")
    try:
        text = block.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise UserError(
            f"{src}: byte {offset + exc.start}: 0x{block[exc.start]:02x} is not UTF-8 text: "
            "not a CSV recording"
        ) from None
    return text.split("\n")


def _line_blocks(path: Path, src: str) -> Iterator[list[str]]:
    """The lines of a text file, a block of about CHUNK_BYTES at a time (no line endings)."""
    require_regular(path, "CSV recording", UserError)  # a FIFO would block the open
    try:
        fh = path.open("rb")
    except FileNotFoundError:
        raise UserError(f"{src}: recording not found") from None
    except OSError as exc:
        raise UserError(f"{src}: cannot read recording: {exc.strerror}") from None
    offset, rest = 0, b""
    with fh:
        while True:
            try:
                block = fh.read(CHUNK_BYTES)
            except OSError as exc:
                raise UserError(f"{src}: cannot read recording: {exc.strerror}") from None
            if not block:
                break
            block = rest + block
            cut = block.rfind(b"\n") + 1
            if cut == 0:
                rest = block
                continue
            lines = _decode(block[: cut - 1], src, offset)
            yield [ln[:-1] if ln.endswith("\r") else ln for ln in lines]
            offset += cut
            rest = block[cut:]
    if rest:
        lines = _decode(rest, src, offset)
        yield [ln[:-1] if ln.endswith("\r") else ln for ln in lines]


def _count_lines(path: Path) -> int:
    """Lines of a file (a last line without a newline counts), to preallocate the arrays."""
    n, last = 0, b"\n"
    try:
        with path.open("rb") as fh:
            while block := fh.read(CHUNK_BYTES):
                n += block.count(b"\n")
                last = block[-1:]
    except OSError:
        pass  # reported by the reader with the file's name
    return n + (last != b"\n")


def count_columns(path: Path, delimiter: str = ",") -> int:
    """Fields in the first non-empty line of a CSV file (binary files: a clear error)."""
    for lines in _line_blocks(Path(path), str(path)):
        for line in lines:
            if line.strip():
                return line.count(delimiter) + 1
    raise UserError(f"{path}: recording is empty")


def _parse_block(
    lines: list[str], first_row: int, cmap: ColumnMap, used: list[int], src: str
) -> tuple[FloatArray, dict[int, str]]:
    """Used columns of ``lines`` as (L, C) floats: numpy's C parser when every row is sound,
    else the row-by-row parser that names each bad row."""
    d = cmap.delimiter
    sound = all(ln.strip() for ln in lines)
    if sound and cmap.columns is not None:
        sound = all(ln.count(d) == cmap.columns - 1 for ln in lines)
    if sound:
        try:
            arr = np.loadtxt(
                lines, delimiter=d, usecols=[c - 1 for c in used], ndmin=2, comments=None
            )
            if arr.shape == (len(lines), len(used)):
                return arr, {}
        except ValueError:
            pass
    return _parse_fields(lines, first_row, cmap, src, used)


def load_csv(
    path: str | Path,
    columns: ColumnMap | str | Path,
    *,
    rows: tuple[int, int] | None = None,
    bad_rows: BadRows | None = None,
    keep_extra: bool = True,
    progress: Callable[[int, int], None] | None = None,
) -> Recording:
    """Read a CSV recording through a column map.

    The file is read in blocks into preallocated float arrays (memory: the result plus one
    block), so a recording of millions of rows costs about 8 bytes per used value.

    Args:
        path: the CSV file (no header unless the map says ``header_rows``).
        columns: a :class:`ColumnMap` or the path of its YAML file.
        rows: 1-based inclusive row range to read; overrides the map's ``rows``.
        bad_rows: ``refuse`` or ``drop``; overrides the map's ``bad_rows``.
        keep_extra: read the map's ``extra`` columns (replay does not need them).
        progress: called as ``progress(rows_read, rows_total)`` after each block.

    Returns:
        A :class:`Recording` with ``t`` (N,) [s], ``q``/``qd``/``tau`` (N, n) in SI units.

    Raises:
        UserError: naming the file, row and column of the first problem.
    """
    path = Path(path)
    cmap = load_column_map(columns)
    if not keep_extra and cmap.extra:
        cmap = cmap.model_copy(update={"extra": {}})
    policy: BadRows = bad_rows or cmap.bad_rows
    row_range = rows if rows is not None else cmap.rows
    src = str(path)
    used = _layout(cmap)
    col = {c: i for i, c in enumerate(used)}
    require_regular(path, "CSV recording", UserError)
    total = _count_lines(path)
    lo, hi = row_range if row_range is not None else (1, total)
    first_row = max(cmap.header_rows + 1, lo)
    capacity = max(min(hi, total) - first_row + 1, 1)
    data = np.full((capacity, len(used)), np.nan)
    bad: dict[int, str] = {}
    n = 0  # rows stored
    last_nonempty = -1
    row = 0  # 1-based number of the last line seen
    checked_layout = False
    for lines in _line_blocks(path, src):
        start = row + 1
        row += len(lines)
        a = max(first_row - start, 0)
        b = min(hi - start + 1, len(lines))
        if b <= a:
            if start > hi:
                break
            continue
        block = lines[a:b]
        block_row = start + a
        if not checked_layout and cmap.columns is not None:
            counts = np.array([ln.count(cmap.delimiter) + 1 for ln in block if ln.strip()])
            if counts.size:
                checked_layout = True
                typical = int(np.bincount(counts).argmax())
                if typical != cmap.columns:
                    raise UserError(
                        f"{src}: rows have {typical} columns, column map '{cmap.name}' expects "
                        f"{cmap.columns} (row {block_row + int(np.argmax(counts == typical))}); "
                        f"use the column map of this layout (--columns)"
                    )
        arr, block_bad = _parse_block(block, block_row, cmap, used, src)
        if n + len(block) > data.shape[0]:  # more lines than newlines (a lone \r): grow
            grown = np.full((max(2 * data.shape[0], n + len(block)), len(used)), np.nan)
            grown[:n] = data[:n]
            data = grown
        data[n : n + len(block)] = arr
        bad.update(block_bad)
        last = next((i for i in range(len(block) - 1, -1, -1) if block[i].strip()), None)
        if last is not None:
            last_nonempty = n + last
        n += len(block)
        if progress is not None:
            progress(min(row, hi) - first_row + 1, min(hi, total) - first_row + 1)
    n_lines = last_nonempty + 1  # trailing empty lines are not rows
    bad = {r: why for r, why in bad.items() if r < first_row + n_lines}
    if row_range is not None and hi > first_row + n_lines - 1:
        raise UserError(
            f"{src}: rows {lo}-{hi} requested but the file ends at row {first_row + n_lines - 1}"
        )
    if n_lines < MIN_SAMPLES:
        raise UserError(
            f"{src}: too short: {max(n_lines, 0)} rows, at least {MIN_SAMPLES} are needed"
        )
    data = data[:n_lines]

    _check_values(data, first_row, cmap, bad)
    t_all = data[:, col[cmap.time]] * cmap.time_scale
    _check_time(t_all, first_row, cmap.max_time_step, bad)
    del t_all

    if bad:
        bad_list = sorted(bad)
        first = bad_list[0]
        if policy == "refuse":
            more = (
                f" ({len(bad_list)} bad rows in all: {_ranges(bad_list)})" if len(bad) > 1 else ""
            )
            raise UserError(
                f"{src}: row {first}: {bad[first]}{more}; fix the file, choose a row range, "
                f"or drop bad rows with a warning (bad_rows: drop / --drop-bad-rows)"
            )
        if len(bad_list) > MAX_DROP_FRACTION * n_lines:
            raise UserError(
                f"{src}: {len(bad_list)} of {n_lines} rows are bad (first: row {first}: "
                f"{bad[first]}); more than {MAX_DROP_FRACTION:.0%} is not dropped"
            )
        note = (
            f"{src}: dropped {len(bad_list)} bad rows ({_ranges(bad_list)}); "
            f"row {first}: {bad[first]}"
        )
        log.warning(note)
        notes = [note]
        keep = np.ones(n_lines, dtype=bool)
        keep[[r - first_row for r in bad]] = False
        data = data[keep]
        row_numbers = np.arange(first_row, first_row + n_lines, dtype=np.int64)[keep]
    else:
        notes = []
        row_numbers = np.arange(first_row, first_row + n_lines, dtype=np.int64)
    if data.shape[0] < MIN_SAMPLES:
        raise UserError(
            f"{src}: too short: {data.shape[0]} good rows, at least {MIN_SAMPLES} needed"
        )

    shared = len(used) != len(cmap.used_columns())  # a column read as two quantities

    def cols(cs: list[int]) -> FloatArray:
        """(N, k) columns: a view of the stored block when they sit side by side (no copy:
        rows stay contiguous for the per-sample loops), else a copy."""
        idx = [col[c] for c in cs]
        if not shared and idx == list(range(idx[0], idx[0] + len(idx))):
            return data[:, idx[0] : idx[0] + len(idx)]
        return np.ascontiguousarray(data[:, idx])

    if cmap.current is not None:
        assert cmap.current_to_torque is not None
        tau = cols(cmap.current)
        tau *= np.asarray(cmap.current_to_torque)
    else:
        assert cmap.torque is not None
        tau = cols(cmap.torque)
    t = data[:, col[cmap.time]] * cmap.time_scale
    q, qd = cols(cmap.q), cols(cmap.qd)
    extra = {name: cols(cs) for name, cs in cmap.extra.items()}
    return Recording(
        t=t, q=q, qd=qd, tau=tau, source=src, rows=row_numbers, extra=extra, notes=notes
    )


# ------------------------------------------------------------------------------ MCAP input


def load_mcap(path: str | Path, topic: str | None = None) -> Recording:
    """Read a joint-state log written by :mod:`hofto_hw.recording` (sensor_msgs/JointState).

    ``effort`` is the joint torque [N·m]; the log time of each message is ``t`` [s].
    """
    from hofto_hw.recording.reader import read_joint_states

    js = read_joint_states(path, topic=topic)
    src = str(path)
    if js.t.shape[0] < MIN_SAMPLES:
        raise UserError(f"{src}: too short: {js.t.shape[0]} joint states, at least {MIN_SAMPLES}")
    steps = np.diff(js.t)
    if np.any(steps <= 0.0):
        k = int(np.argmax(steps <= 0.0)) + 1
        raise UserError(f"{src}: message {k + 1}: time {js.t[k]:.6f} s does not advance")
    for name, arr in (("position", js.q), ("velocity", js.qd), ("effort", js.tau)):
        finite = np.isfinite(arr)
        if not finite.all():
            k, j = (int(v) for v in np.argwhere(~finite)[0])
            raise UserError(f"{src}: message {k + 1}: {name}[{j}] is not finite")
    return Recording(
        t=js.t,
        q=js.q,
        qd=js.qd,
        tau=js.tau,
        source=src,
        rows=np.arange(1, js.t.shape[0] + 1, dtype=np.int64),
        extra={},
    )


def load_recording(
    path: str | Path,
    columns: ColumnMap | str | Path | None = None,
    *,
    rows: tuple[int, int] | None = None,
    bad_rows: BadRows | None = None,
    keep_extra: bool = True,
    progress: Callable[[int, int], None] | None = None,
) -> Recording:
    """Read a recording by its extension: ``.mcap`` (our logs) or CSV (needs ``columns``)."""
    path = Path(path)
    if path.suffix.lower() == ".mcap":
        rec = load_mcap(path)
        if rows is not None:
            rec = rec.select(slice(rows[0] - 1, rows[1]))
        return rec
    if columns is None:
        raise UserError(f"{path}: a CSV recording needs a column map (--columns FILE)")
    return load_csv(
        path, columns, rows=rows, bad_rows=bad_rows, keep_extra=keep_extra, progress=progress
    )


# ---------------------------------------------------------------------------- conditioning


def sample_rate(t: FloatArray) -> float:
    """Nominal sample rate 1 / median(dt) [Hz] of time stamps ``t`` (N,) [s]."""
    return float(1.0 / np.median(np.diff(t)))


def lowpass(
    x: FloatArray, t: FloatArray, cutoff_hz: float, order: int = 4, source: str = ""
) -> FloatArray:
    """Zero-phase Butterworth low-pass of ``x`` (N, ...) along axis 0.

    The filter is designed at the median sample rate of ``t`` (N,) [s]: the jitter of the
    time stamps is small against the pass band, so treating the samples as evenly spaced
    here only smears the cut-off slightly; derivatives still use the real time stamps.
    """
    fs = sample_rate(t)
    if not 0.0 < cutoff_hz < 0.5 * fs:
        raise UserError(
            f"{source or 'recording'}: cutoff {cutoff_hz:g} Hz must be in (0, {0.5 * fs:.4g}) Hz "
            f"(half the median sample rate)"
        )
    from scipy import signal  # here: seconds of imports the loop's log writer never needs

    sos = signal.butter(order, cutoff_hz, fs=fs, output="sos")
    padlen = 3 * (2 * sos.shape[0] + 1)
    if x.shape[0] <= padlen:
        raise UserError(
            f"{source or 'recording'}: too short to filter: {x.shape[0]} samples, "
            f"more than {padlen} are needed"
        )
    return signal.sosfiltfilt(sos, x, axis=0)


def differentiate(x: FloatArray, t: FloatArray) -> FloatArray:
    """d x / d t of ``x`` (N, ...) at time stamps ``t`` (N,) [s], along axis 0.

    Second-order central differences on the actual, uneven spacing (one-sided at the ends).
    """
    return np.gradient(x, t, axis=0, edge_order=2)


def trim_standstill(rec: Recording, speed: float = 0.01, margin: float = 0.5) -> Recording:
    """Drop standstill at both ends: keep from ``margin`` [s] before the first sample with
    any |qd| > ``speed`` [rad/s] to ``margin`` after the last one. A recording that never
    moves is returned unchanged (with a note)."""
    moving = np.flatnonzero(np.any(np.abs(rec.qd) > speed, axis=1))
    if moving.size == 0:
        out = rec.select(slice(None))
        out.notes.append(f"{rec.source}: no motion above {speed:g} rad/s; nothing trimmed")
        return out
    t0 = rec.t[moving[0]] - margin
    t1 = rec.t[moving[-1]] + margin
    keep = (rec.t >= t0) & (rec.t <= t1)
    out = rec.select(keep)
    out.notes.append(
        f"{rec.source}: trimmed standstill, kept {out.t[0]:.3f}-{out.t[-1]:.3f} s "
        f"(rows {out.rows[0]}-{out.rows[-1]})"
    )
    _check_length(out, "after trimming")
    return out


def decimate(rec: Recording, factor: int) -> Recording:
    """Every ``factor``-th sample. Low-pass first (below the new Nyquist rate): this does not."""
    if factor < 1:
        raise UserError(f"{rec.source}: decimation factor must be >= 1, got {factor}")
    if factor == 1:
        return rec
    out = rec.select(slice(None, None, factor))
    _check_length(out, f"after decimation by {factor}")
    return out


def _check_length(rec: Recording, when: str) -> None:
    if rec.n_samples < MIN_SAMPLES:
        raise UserError(
            f"{rec.source}: too short {when}: {rec.n_samples} samples, at least {MIN_SAMPLES}"
        )


def condition(
    rec: Recording,
    cutoff_hz: float = 10.0,
    *,
    order: int = 4,
    filter_torque: bool = True,
    trim: bool = True,
    trim_speed: float = 0.01,
    trim_margin: float = 0.5,
    decimation: int = 1,
) -> Recording:
    """Offline conditioning for identification (non-causal: never use it in replay).

    Steps: trim standstill at the ends (optional), zero-phase low-pass of qd and (optional)
    tau at ``cutoff_hz`` [Hz], qdd by central differences of the filtered qd on the real
    time stamps, then keep every ``decimation``-th sample (the low-pass must then lie below
    the new Nyquist rate, which is checked).
    """
    out = trim_standstill(rec, trim_speed, trim_margin) if trim else rec.select(slice(None))
    fs = sample_rate(out.t)
    if decimation > 1 and cutoff_hz >= 0.5 * fs / decimation:
        raise UserError(
            f"{rec.source}: cutoff {cutoff_hz:g} Hz is above the Nyquist rate "
            f"{0.5 * fs / decimation:.3g} Hz after decimation by {decimation}"
        )
    out.qd = lowpass(out.qd, out.t, cutoff_hz, order, rec.source)
    if filter_torque:
        out.tau = lowpass(out.tau, out.t, cutoff_hz, order, rec.source)
    out.qdd = differentiate(out.qd, out.t)
    out.notes.append(
        f"{rec.source}: zero-phase low-pass {cutoff_hz:g} Hz (order {order}) on qd"
        + (" and tau" if filter_torque else "")
    )
    return decimate(out, decimation)
