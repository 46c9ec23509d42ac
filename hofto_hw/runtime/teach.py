"""Teach and play in the running loop: ``mode drag --record FILE``, ``mode replay FILE``,
``mode move --joints``.

Everything here is slow path (the control-socket thread, the end of a run): checking the
output file, loading and planning (ruckig point-to-point, the taught path time-scaled by
hofto_hw.control.path_timing), saving the taught path, the replay figures. The tick only
pushes samples into the preallocated recorders of a :class:`Recording` or :class:`Playback`
and plays a planned trajectory one row per tick; it gets them through one-writer request
attributes (``Tick.record_request``, ``Tick.play_request``) set before ``mode_request``.

Recording states (``Recording.state``, written by the tick up to FINISHED, then by the
slow path): ARMED (drag requested, hand not yet on the enabling input), RECORDING, FINISHED
(the drag ended: release, a stop, or the mode left), SAVED or FAILED (``message`` says why).
"""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from hofto_hw.control.joint_motion import MOVE_TO, REPLAY
from hofto_hw.control.path_timing import (
    Limits,
    ReplayPlan,
    Sampled,
    TrajectoryPlayer,
    jerk_limited_move,
    replay_plan,
    replay_trajectory,
)
from hofto_hw.control.taught_path import (
    TaughtPath,
    TaughtPathRecorder,
    load_taught_path,
    save_taught_path,
)
from hofto_hw.errors import UserError
from hofto_hw.model.robot import RobotModel
from hofto_hw.outputs import output_problem

ARMED, RECORDING, FINISHED, SAVED, FAILED = range(5)
STATE_NAMES = {
    ARMED: "armed",
    RECORDING: "recording",
    FINISHED: "finished",
    SAVED: "saved",
    FAILED: "failed",
}


def check_output(file: Path | str, force: bool) -> Path:
    """Refuse (UserError, one line) an output file the taught path must not go to: a folder,
    an existing file without ``force``, a missing folder or one that takes no new file (a
    read-only mount, /proc: probed, :func:`hofto_hw.outputs.output_problem`). Called where
    the request is accepted (the control server's ``mode drag --record``). Returns the path."""
    file = Path(file)
    if file.is_dir():
        raise UserError(f"{file}: is a folder; --record needs a file name")
    if file.exists() or file.is_symlink():
        if not force:
            raise UserError(
                f"{file}: exists; not overwriting it (name a new file, or --force to replace it)"
            )
        if not os.access(file, os.W_OK):
            raise UserError(f"{file}: exists and is not writable")
    parent = file.parent
    if not parent.is_dir():
        raise UserError(f"{file}: folder {parent} does not exist")
    problem = output_problem(file)  # probes the folder: os.access says yes to root anywhere
    if problem is not None:
        raise UserError(f"{file}: {problem}")
    return file


class Recording:
    """A taught path to record while dragging, saved to ``file`` when the drag ends.
    ``capacity`` samples are allocated here, off the tick (later samples are dropped)."""

    def __init__(self, file: Path | None, force: bool, model: RobotModel, capacity: int) -> None:
        self.file = None if file is None else Path(file)
        self.force = force
        self.model = model
        self.recorder = TaughtPathRecorder(model.n, capacity)
        self.state = ARMED
        self.message = ""

    def save(self) -> str:
        """Write the recorded path (slow path); sets ``state`` SAVED or FAILED and returns
        the message. Without ``force`` the file is created exclusively, so a file that
        appeared since the request is never replaced."""
        rec = self.recorder
        if self.file is None:  # kept in memory (the scripted replay of hofto-hw run)
            self.state = SAVED
            self.message = f"taught path: {rec.count} samples (in memory)"
            return self.message
        if rec.count < 2:
            self.state = FAILED
            self.message = (
                f"{self.file}: not written: nothing was taught ({rec.count} samples; "
                "the enabling input was not held in drag mode)"
            )
            return self.message
        path = rec.path(self.model)
        tmp = self.file.with_name(f".{self.file.name}.{os.getpid()}.partial")
        try:
            save_taught_path(path, tmp)
            if self.force:
                os.replace(tmp, self.file)
            else:
                os.link(tmp, self.file)  # exclusive: fails if the name exists by now
                tmp.unlink()
        except FileExistsError:
            self.state = FAILED
            self.message = f"{self.file}: appeared meanwhile, not replaced; taught path in {tmp}"
            return self.message
        except OSError as exc:
            tmp.unlink(missing_ok=True)
            self.state = FAILED
            self.message = f"{self.file}: cannot write the taught path: {exc.strerror}"
            return self.message
        self.state = SAVED
        dropped = " (buffer full: later samples dropped)" if rec.overflow else ""
        self.message = (
            f"taught path: {rec.count} samples, {path.t[-1]:.2f} s, saved to {self.file}{dropped}"
        )
        return self.message

    def status(self) -> dict[str, Any]:
        return {
            "file": None if self.file is None else str(self.file),
            "state": STATE_NAMES[self.state],
            "samples": int(self.recorder.count),
            "message": self.message,
        }


def save_finished(tick: Any, at_end: bool = False) -> str:
    """Save the tick's recording once the drag has ended (or, ``at_end`` of the run, whatever
    was recorded); returns the message, "" when there is nothing to save."""
    rec = tick.recording
    if rec is None or rec.file is None:
        return ""
    if rec.state == FINISHED or (at_end and rec.state in (ARMED, RECORDING)):
        return rec.save()
    return ""


class Playback:
    """A planned trajectory for the tick: a taught-path replay (``kind`` 'replay') or a move
    to a joint target ('move'). ``executed``: the measured q of every played tick
    (preallocated), for the figures."""

    def __init__(
        self,
        kind: str,
        traj: Sampled,
        limits: Limits,
        taught: TaughtPath | None = None,
        file: Path | None = None,
    ) -> None:
        self.kind = kind
        self.mode = REPLAY if kind == "replay" else MOVE_TO
        self.traj = traj
        self.limits = limits
        self.taught = taught
        self.file = file
        self.player = TrajectoryPlayer(traj)
        self.executed = TaughtPathRecorder(traj.q.shape[1], traj.q.shape[0] + 1)
        self.max_jerk_ratio = 0.0
        if traj.q.shape[0] > 1:  # the commanded jerk, finite differences at the tick period
            jerk = np.abs(np.diff(traj.qdd, axis=0)).max(axis=0) / traj.dt
            self.max_jerk_ratio = float((jerk / limits.jerk).max())

    @property
    def start(self) -> np.ndarray:
        return self.traj.q[0]

    @property
    def completed(self) -> bool:
        return self.player.done

    def figures(self, model: RobotModel, q_now: np.ndarray | None = None) -> dict[str, Any]:
        """Replay figures (slow path): ``max_path_error_mm`` = largest distance from an
        executed tool position (measured q, after the move to the path's start) to the taught
        tool path (its samples, nearest point), ``duration_s`` (planned: move + path),
        ``max_jerk_ratio`` (planned jerk over its limit), ``completed``, ``time_scale``; for a
        move ``final_error_rad``: max |q - target| of ``q_now`` (measured, after the run) or
        of the last played tick."""
        from hofto_hw.experiments.drag_sim import path_error_mm

        out: dict[str, Any] = {
            "kind": self.kind,
            "completed": bool(self.completed),
            "duration_s": round(self.traj.duration, 4),
            "max_jerk_ratio": round(self.max_jerk_ratio, 4),
            "time_scale": round(float(self.traj.scale), 4),
            "max_path_error_mm": None,
        }
        ex = self.executed
        start = self.traj.segments[-1]
        if self.taught is not None and ex.count > start + 1:
            data = model.create_data()
            taught = np.array([data.tool_pose(q)[0] for q in self.taught.q])
            done = np.array([data.tool_pose(q)[0] for q in ex.q[start : ex.count]])
            out["max_path_error_mm"] = round(path_error_mm(taught, done), 4)
        if self.kind == "move":  # the arm now (``q_now``), else at the last played tick
            q_end = q_now if q_now is not None else (ex.q[ex.count - 1] if ex.count else None)
            err = math.nan if q_end is None else float(np.abs(q_end - self.traj.q[-1]).max())
            out["final_error_rad"] = round(err, 6)
        return out


def motion_limits(cfg: Any, model: RobotModel) -> Limits:
    """Velocity, acceleration, jerk limits of moves and replay (``motion:`` section)."""
    vel, acc, jerk = cfg.motion.limits(model)
    return Limits(np.array(vel), np.array(acc), np.array(jerk))


def plan_replay(
    file: Path | str, q_now: np.ndarray, model: RobotModel, limits: Limits, dt: float
) -> Playback:
    """Load and check the taught path (one-line UserError: missing, binary, truncated,
    another robot, out of limits), plan the move to its start and the time-scaled path."""
    path = load_taught_path(file, model)
    return plan_path(path, q_now, limits, dt, file=Path(file))


def stream_replay(
    file: Path | str, q_now: np.ndarray, model: RobotModel, limits: Limits, dt: float
) -> tuple[ReplayPlan, str, int, Path]:
    """:func:`plan_replay` for a planner that streams the rows: the plan (the fit and its
    scale done, the rows sampled on demand), its kind, mode and file."""
    path = load_taught_path(file, model)
    return replay_plan(q_now, path.t, path.q, limits, dt), "replay", REPLAY, Path(file)


def plan_path(
    path: TaughtPath, q_now: np.ndarray, limits: Limits, dt: float, file: Path | None = None
) -> Playback:
    """The move from ``q_now`` to the taught path's start, then the time-scaled path."""
    traj = replay_trajectory(q_now, path.t, path.q, limits, dt)
    return Playback("replay", traj, limits, taught=path, file=file)


def parse_joints(text: str, degrees: bool = False) -> np.ndarray:
    """``q1,...,qn`` [rad, or degrees with ``degrees``] -> array; UserError for a non-number."""
    parts = [p.strip() for p in text.split(",")]
    try:
        values = np.array([float(p) for p in parts])
    except ValueError:
        raise UserError(
            f"--joints: {text!r}: expected comma-separated numbers (q1,...,qn)"
        ) from None
    return np.radians(values) if degrees else values


def check_target(q: np.ndarray, model: RobotModel) -> None:
    """Refuse a joint target (one line): wrong count, non-finite, outside the joint limits."""
    if q.shape != (model.n,):
        raise UserError(f"--joints: {q.size} values, {model.name} has {model.n} joints")
    lim = model.limits
    for j in range(model.n):
        name = model.joint_names[j]
        if not math.isfinite(q[j]):
            raise UserError(f"--joints: {name}: {q[j]} is not a finite number")
        if not lim.position_lower[j] <= q[j] <= lim.position_upper[j]:
            raise UserError(
                f"--joints: {name}: {q[j]:.4f} rad outside its limits "
                f"[{lim.position_lower[j]:.4f}, {lim.position_upper[j]:.4f}] rad"
            )


def plan_move(
    q_target: np.ndarray, q_now: np.ndarray, model: RobotModel, limits: Limits, dt: float
) -> Playback:
    """A jerk-limited rest-to-rest move (ruckig) to a checked joint target [rad]."""
    check_target(q_target, model)
    return Playback("move", jerk_limited_move(q_now, q_target, limits, dt), limits)


def plan_linear(
    target: np.ndarray, q_now: np.ndarray, model: RobotModel, limits: Limits, dt: float
) -> Playback:
    """A straight tool line to ``target`` ([x, y, z, rx, ry, rz], base frame) from the held
    position: the joint path of hofto_hw.control.cartesian (refused before anything moves
    when unreachable or out of limits), at rest at both ends (a cosine profile along the
    line), time-scaled into the limits like a taught path (jerk-limited)."""
    from hofto_hw.control.cartesian import linear_joint_path

    qs = linear_joint_path(model.create_data(), q_now, target)
    k = qs.shape[0]
    tau = np.linspace(0.0, 1.0, max(k, 200))
    s = 0.5 * (1.0 - np.cos(np.pi * tau)) * (k - 1)  # sample index along the line
    q = np.column_stack([np.interp(s, np.arange(k), qs[:, j]) for j in range(qs.shape[1])])
    traj = replay_trajectory(q_now, tau * max(1.0, 0.01 * k), q, limits, dt)
    return Playback("linear", traj, limits)
