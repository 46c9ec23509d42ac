"""The taught path: joint positions with time stamps, recorded while dragging, and its file.

Recording (per tick, allocation-free): :class:`TaughtPathRecorder` fills preallocated arrays;
saving and loading happen outside the tick.

File format: CSV, chosen over MCAP because a taught path is a small table a person may read,
diff or edit (10 s at 1 kHz = 10,000 rows, ~0.9 MB) and needs no ROS tooling to open. Layout:

    # hofto-hw taught path v1
    # robot: er3a
    t,joint_1,joint_2,...        (time [s] from the first sample, positions [rad])
    0.000000,0.0000000000,...

:func:`load_taught_path` refuses, in one line naming the file (and line): a missing, empty,
binary or non-UTF-8 file, another format, a path for another robot or other joints, a short
or non-numeric row (a truncated file), non-finite values, time that does not increase, fewer
than 2 samples, and positions outside the robot's joint limits.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hofto_hw.config.loader import read_bounded
from hofto_hw.errors import UserError
from hofto_hw.model.robot import RobotModel

MAGIC = "# hofto-hw taught path v1"
#: largest taught-path file read [bytes]: ~90 bytes a row, so 256 MiB is ~50 min at 1 kHz
#: (motion.record_seconds allows an hour at most)
MAX_BYTES = 256 << 20


@dataclass
class TaughtPath:
    """t (N,) [s] from 0, q (N, n) [rad], for ``robot`` with ``joints``."""

    t: np.ndarray
    q: np.ndarray
    robot: str
    joints: list[str]


class TaughtPathRecorder:
    """Preallocated recorder: ``push(t, q)`` per tick (no allocation); ``count`` samples;
    ``overflow`` True when the capacity ran out (later samples are dropped, not wrapped:
    a path must keep its start)."""

    def __init__(self, n: int, capacity: int) -> None:
        self.t = np.zeros(capacity)
        self.q = np.zeros((capacity, n))
        self.count = 0
        self.overflow = False

    def clear(self) -> None:
        self.count = 0
        self.overflow = False

    def push(self, t: float, q: np.ndarray) -> None:
        """Record joint positions ``q`` (n,) [rad] at time ``t`` [s]."""
        i = self.count
        if i >= self.t.shape[0]:
            self.overflow = True
            return
        self.t[i] = t
        self.q[i] = q
        self.count = i + 1

    def path(self, model: RobotModel) -> TaughtPath:
        """The recorded samples (copies), time from the first sample."""
        k = self.count
        t = self.t[:k] - (self.t[0] if k else 0.0)
        return TaughtPath(t, self.q[:k].copy(), model.name, list(model.joint_names))


def save_taught_path(path: TaughtPath, file: Path | str) -> Path:
    """Write ``path`` to ``file`` (CSV, see module docstring); returns the file."""
    file = Path(file)
    if path.t.shape[0] < 2:
        raise UserError(f"{file}: nothing to save: the taught path has {path.t.shape[0]} samples")
    lines = [MAGIC, f"# robot: {path.robot}", "t," + ",".join(path.joints)]
    for tk, qk in zip(path.t, path.q, strict=True):
        lines.append(f"{tk:.6f}," + ",".join(f"{v:.10f}" for v in qk))
    file.parent.mkdir(parents=True, exist_ok=True)
    file.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return file


def load_taught_path(file: Path | str, model: RobotModel) -> TaughtPath:
    """Read and check a taught-path file for ``model`` (raises UserError, one line)."""
    file = Path(file)
    raw = read_bounded(file, "taught-path file", MAX_BYTES, UserError)
    if not raw:
        raise UserError(f"{file}: empty file, not a taught path")
    if b"\x00" in raw[:4096]:
        raise UserError(f"{file}: binary data, not a taught path (expected CSV text)")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError:
        raise UserError(f"{file}: not UTF-8 text, not a taught path") from None
    lines = text.splitlines()
    if not lines or lines[0].strip() != MAGIC:
        raise UserError(f"{file}: line 1: expected {MAGIC!r}: not a hofto-hw taught path")
    if len(lines) < 3 or not lines[1].startswith("# robot:"):
        raise UserError(f"{file}: line 2: expected '# robot: NAME'")
    robot = lines[1].split(":", 1)[1].strip()
    if robot != model.name:
        raise UserError(f"{file}: taught on robot {robot!r}, this robot is {model.name!r}")
    header = lines[2].strip().split(",")
    joints = header[1:]
    if header[0] != "t" or joints != list(model.joint_names):
        raise UserError(
            f"{file}: line 3: columns {header} do not match t + this robot's joints "
            f"{model.joint_names}"
        )
    n = model.n
    data = _parse_rows(text, n)
    if data is None:  # the slow line-by-line read, for the line that is wrong
        data = _check_rows(file, lines, n)
    t, q = data[:, 0], data[:, 1:]
    bad = np.flatnonzero(np.diff(t) <= 0.0)
    if bad.size:
        raise UserError(f"{file}: line {bad[0] + 5}: time does not increase ({t[bad[0] + 1]} s)")
    lim = model.limits
    for j in range(n):
        lo, hi = q[:, j].min(), q[:, j].max()
        if lo < lim.position_lower[j] or hi > lim.position_upper[j]:
            raise UserError(
                f"{file}: joint {model.joint_names[j]}: positions [{lo:.3f}, {hi:.3f}] rad "
                f"outside its limits [{lim.position_lower[j]:.3f}, {lim.position_upper[j]:.3f}]"
            )
    return TaughtPath(t - t[0], q, robot, joints)


def _parse_rows(text: str, n: int) -> np.ndarray | None:
    """The samples (rows, n + 1) below the three header lines when every one is right (numpy's
    C reader: 0.4 s for a 300 s path, where the checked loop takes ~8 s); None otherwise."""
    import io
    import warnings

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # an empty body: None, said by the checked read
            data = np.loadtxt(io.StringIO(text), delimiter=",", comments=None, skiprows=3, ndmin=2)
    except ValueError:
        return None
    if data.shape[0] < 2 or data.shape[1] != n + 1 or not np.isfinite(data).all():
        return None
    return data


def _check_rows(file: Path, lines: list[str], n: int) -> np.ndarray:
    """The samples read line by line: one line naming the first line that is wrong."""
    rows = []
    for i, line in enumerate(lines[3:], start=4):
        if not line.strip():
            continue
        parts = line.split(",")
        if len(parts) != n + 1:
            raise UserError(
                f"{file}: line {i}: {len(parts)} values, expected {n + 1} (truncated file?)"
            )
        try:
            values = [float(p) for p in parts]
        except ValueError:
            raise UserError(f"{file}: line {i}: not a number in {line[:60]!r}") from None
        if not all(math.isfinite(v) for v in values):
            raise UserError(f"{file}: line {i}: non-finite value")
        rows.append(values)
    if len(rows) < 2:
        raise UserError(f"{file}: {len(rows)} samples; a taught path needs at least 2")
    return np.asarray(rows)
