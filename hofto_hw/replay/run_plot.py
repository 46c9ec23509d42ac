"""A picture of a run from its flight log (`hofto-hw log plot`, `hofto-hw run --plot`).

Panels (each titled; :func:`run_figure` returns the figure, tests read the titles):

- the joint positions, safety events marked (collision red, contact orange, others grey);
- per joint, the detector observer's estimated external torque against the contact and
  collision thresholds the loop's monitor used (``safety.collision.CollisionLevels`` re-run on
  the recorded estimates: the thresholds move with speed, acceleration phase and reversals);
- the first stop: joint speeds from the fault to standstill and the mean deceleration;
- drag: the tool speed while the controller was in drag mode (from q, qd and the tool Jacobian);
- loop timing: compute and wake-up time per tick against the period.

Everything comes from the log and its attachments (config, URDF): the figure can be drawn
anywhere, long after the run. matplotlib's Figure without pyplot (no display, no global state).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pinocchio as pin
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from hofto_hw.control.joint_motion import DRAG
from hofto_hw.errors import UserError
from hofto_hw.replay.flight_log import FlightLog, RecordedEvent

#: speed below which a joint counts as stopped [rad/s] (for the stop panel's duration)
STANDSTILL = 0.01
#: events drawn in their own colour; other events grey, standstill reports not at all
_EVENT_COLOURS = {"collision": "C3", "contact": "C1"}
_QUIET_EVENTS = {"standstill", "reset"}


def save_figure(fig: Figure, path: Path, dpi: int = 80) -> Path:
    """Write ``fig`` as PNG exactly at ``path`` (whatever its suffix); one-line error."""
    try:
        fig.savefig(path, dpi=dpi, format="png")
    except OSError as exc:
        raise UserError(f"{path}: cannot write plot: {exc.strerror or exc}") from None
    return path


def titles(fig: Figure) -> list[str]:
    """The panels' titles, in drawing order (what the tests check)."""
    return [ax.get_title() for ax in fig.axes if ax.get_title()]


def _thresholds(log: FlightLog) -> tuple[str, np.ndarray | None, tuple[str, ...]]:
    """(detector observer, thresholds (N, L, n) [N·m] of its row (NaN on ticks the monitor
    did not judge) or None, level names) by re-running the run's monitor on the log."""
    from hofto_hw.replay.levels_track import detector_levels, level_names, track_thresholds
    from hofto_hw.replay.reproduce import loop_dt, profile_switches, run_setup

    found = detector_levels(log)
    if found is None:
        return log.metadata.get("detector", ""), None, ()
    observer, row, mon = found
    assert log.monitored is not None and log.qdd_cmd is not None
    est = np.stack([log.tau_ext[o] for o in log.observers], axis=1)
    rate = log.metadata.get("rate_hz") or run_setup(log).config.loop.rate_hz
    dt = loop_dt(log, float(rate))
    h = dt if log.sample_dt is None else np.where(log.sample_dt > 0.0, log.sample_dt, dt)
    mon.reset()
    thr = track_thresholds(
        mon, row, est, log.qd, log.qdd_cmd, h, log.ticks, log.monitored, profile_switches(log)
    )
    return observer, thr, level_names(mon)


def _mark_events(ax: Axes, events: list[RecordedEvent], t0: float, label: bool = False) -> None:
    seen: set[str] = set()
    for ev in events:
        if ev.kind_name in _QUIET_EVENTS:
            continue
        colour = _EVENT_COLOURS.get(ev.kind_name, "0.5")
        text = ev.kind_name if label and ev.kind_name not in seen else None
        seen.add(ev.kind_name)
        ax.axvline(ev.t - t0, color=colour, lw=0.9, ls="--", label=text)


def _first_stop(log: FlightLog) -> RecordedEvent | None:
    for ev in log.events:
        if ev.category >= 0 and ev.kind_name not in _QUIET_EVENTS and ev.kind_name != "contact":
            return ev
    return None


def _stop_panel(ax: Axes, log: FlightLog, t: np.ndarray) -> None:
    ev = _first_stop(log)
    if ev is None:
        ax.set_title("stop: none in this run")
        ax.text(0.5, 0.5, "no stop", ha="center", va="center", transform=ax.transAxes)
        return
    t_ev = ev.t - log.t[0]
    k0 = int(np.searchsorted(t, t_ev))
    speed = np.abs(log.qd)
    still = np.flatnonzero(np.all(speed[k0:] < STANDSTILL, axis=1))
    k1 = k0 + int(still[0]) if len(still) else len(t) - 1
    duration = max(t[k1] - t[k0], 1e-9)
    decel = float(np.max(speed[k0] / duration)) if k1 > k0 else 0.0
    lo = int(np.searchsorted(t, t_ev - 0.05))
    hi = min(len(t), k1 + int(0.1 * len(t) / max(t[-1], 1e-9)) + 1)
    for j in range(speed.shape[1]):
        ax.plot(t[lo:hi], speed[lo:hi, j], lw=0.9, label=f"joint {j + 1}")
    ax.axvline(t_ev, color=_EVENT_COLOURS.get(ev.kind_name, "0.5"), ls="--", lw=0.9)
    ax.axvline(t[k1], color="0.3", ls=":", lw=0.9)
    ax.set_ylabel("|qd| [rad/s]")
    ax.legend(loc="upper right", fontsize=6, ncol=2)
    ax.set_title(
        f"stop: {ev.kind_name.replace('_', ' ')} (category {ev.category}) at {t_ev:.3f} s, "
        f"at rest after {1e3 * (t[k1] - t[k0]):.0f} ms, mean deceleration up to "
        f"{decel:.1f} rad/s²"
    )


def _drag_panel(ax: Axes, log: FlightLog, t: np.ndarray) -> None:
    drag = np.zeros(log.n_ticks, dtype=bool) if log.mode is None else log.mode == DRAG
    if not drag.any():
        ax.set_title("drag: none in this run")
        ax.text(0.5, 0.5, "no drag", ha="center", va="center", transform=ax.transAxes)
        return
    speed = np.full(log.n_ticks, np.nan)
    speed[drag] = _tool_speed(log, np.flatnonzero(drag))
    ax.plot(t, 1e3 * speed, lw=0.9, color="C2")
    ax.set_xlim(t[drag][0] - 0.2, t[drag][-1] + 0.2)
    ax.set_ylabel("tool speed [mm/s]")
    ax.set_title(
        f"drag: tool speed, max {1e3 * np.nanmax(speed):.1f} mm/s over "
        f"{t[drag][-1] - t[drag][0]:.2f} s in drag mode"
    )


def _tool_speed(log: FlightLog, ticks: np.ndarray) -> np.ndarray:
    """|v| [m/s] of the tool origin at ``ticks`` (indices) from q, qd (the URDF's kinematics)."""
    from hofto_hw.replay.reproduce import run_setup

    model = run_setup(log).model
    data = model.pin_model.createData()
    out = np.empty(len(ticks))
    for i, k in enumerate(ticks):
        jac = pin.computeFrameJacobian(
            model.pin_model, data, log.q[k], model.tool_frame_id, pin.LOCAL_WORLD_ALIGNED
        )
        out[i] = float(np.linalg.norm(jac[:3] @ log.qd[k]))
    return out


def _timing_panel(ax: Axes, log: FlightLog, t: np.ndarray) -> None:
    if log.compute_us is None or log.wakeup_us is None:
        ax.set_title("loop timing: not in this log")
        return
    rate = float(log.metadata.get("rate_hz", "0") or 0.0)
    ax.plot(t, log.compute_us, lw=0.5, color="C0", label="compute")
    ax.plot(t, log.wakeup_us, lw=0.5, color="C1", label="wake-up latency")
    if rate > 0:
        ax.axhline(1e6 / rate, color="C3", lw=0.8, label="period")
    ax.set_ylabel("[µs]")
    ax.set_yscale("symlog", linthresh=100.0)
    ax.set_ylim(bottom=0.0)
    ax.legend(loc="upper right", fontsize=7, ncol=3)
    c99, w99 = np.percentile(log.compute_us, 99), np.percentile(log.wakeup_us, 99)
    wake = f"wake-up p99 {w99:.0f} µs" if log.wakeup_us.any() else "no wake-up (sim clock)"
    ax.set_title(
        f"loop timing: compute median {np.median(log.compute_us):.0f} µs, p99 {c99:.0f} µs; {wake}"
    )


def run_figure(log: FlightLog) -> Figure:
    """The figure of a run (see the module docstring)."""
    t = log.t - log.t[0]
    n = len(log.joint_names)
    detector, thr, levels = _thresholds(log)
    rows_torque = (n + 1) // 2
    fig = Figure(figsize=(13, 3.0 * (rows_torque + 3)))
    gs = fig.add_gridspec(rows_torque + 3, 2)
    ax = fig.add_subplot(gs[0, :])
    for j in range(n):
        ax.plot(t, log.q[:, j], lw=0.9, label=log.joint_names[j])
    _mark_events(ax, log.events, log.t[0], label=True)
    ax.set_ylabel("q [rad]")
    ax.legend(loc="upper right", fontsize=7, ncol=n + 3)
    ax.set_title("joint positions")
    first = ax
    est = log.tau_ext.get(detector)
    for j in range(n):
        ax = fig.add_subplot(gs[1 + j // 2, j % 2], sharex=first)
        if est is not None:
            ax.plot(t, est[:, j], lw=0.8, color="C0", label=f"{detector} estimate")
        if thr is not None:
            for lv, name in enumerate(levels):
                colour = _EVENT_COLOURS[name]
                ax.plot(t, thr[:, lv, j], lw=0.7, color=colour, label=f"{name} threshold")
                ax.plot(t, -thr[:, lv, j], lw=0.7, color=colour)
        _mark_events(ax, log.events, log.t[0])
        ax.set_ylabel("[N·m]")
        ax.grid(alpha=0.3)
        if j == 0:
            ax.legend(loc="upper right", fontsize=6)
        ax.set_title(f"{log.joint_names[j]}: estimated external torque vs thresholds")
    ax = fig.add_subplot(gs[rows_torque + 1, 0])
    _stop_panel(ax, log, t)
    ax = fig.add_subplot(gs[rows_torque + 1, 1])
    _drag_panel(ax, log, t)
    ax = fig.add_subplot(gs[rows_torque + 2, :], sharex=first)
    _timing_panel(ax, log, t)
    ax.set_xlabel("time since the start of the log [s]")
    for a in fig.axes:
        a.title.set_fontsize(9)
    robot = log.metadata.get("robot", "")
    fig.suptitle(
        f"{log.path.name}: {robot}, {log.n_ticks} ticks, {t[-1]:.2f} s, detector {detector}",
        fontsize=11,
    )
    fig.tight_layout(rect=(0.0, 0.0, 1.0, 0.985))
    return fig


def replay_figure(log: FlightLog, replayed: dict[str, np.ndarray], observer: str,
                  replayed_tick: int | None) -> Figure:  # fmt: skip
    """`hofto-hw replay RUN.mcap --plot`: ``observer``'s recorded and replayed estimate per
    joint, the recorded collision (red) and the replayed first detection (black) marked."""
    t = log.t - log.t[0]
    n = len(log.joint_names)
    fig = Figure(figsize=(12, 1.9 * n + 1))
    axes = fig.subplots(n, 1, sharex=True, squeeze=False)[:, 0]
    rec, rep = log.tau_ext[observer], replayed[observer]
    collisions = [e for e in log.events if e.kind_name == "collision"]
    for j, ax in enumerate(axes):
        ax.plot(t, rec[:, j], lw=1.6, color="C0", alpha=0.6, label="recorded")
        ax.plot(t, rep[:, j], lw=0.7, color="C1", ls="--", label="replayed")
        if collisions:
            ax.axvline(collisions[0].t - log.t[0], color="C3", lw=0.9, label="recorded collision")
        if replayed_tick is not None:
            k = int(np.searchsorted(log.ticks, replayed_tick))
            ax.axvline(t[min(k, len(t) - 1)], color="k", lw=0.7, ls=":", label="replayed detection")
        diff = float(np.max(np.abs(rep[:, j] - rec[:, j])))
        ax.set_ylabel("[N·m]")
        ax.grid(alpha=0.3)
        ax.set_title(
            f"{log.joint_names[j]}: {observer} estimate, recorded vs replayed "
            f"(max |difference| {diff:.3g} N·m)",
            fontsize=9,
        )
    axes[0].legend(loc="upper right", fontsize=7, ncol=4)
    axes[-1].set_xlabel("time since the start of the log [s]")
    fig.suptitle(f"{log.path.name}: replay of the recorded observers", fontsize=11)
    fig.tight_layout(rect=(0.0, 0.0, 1.0, 0.98))
    return fig


def plot_run(log_path: Path, out: Path) -> list[str]:
    """Read the flight log ``log_path``, write its figure to ``out``; returns the titles."""
    from hofto_hw.replay.flight_log import read_flight_log

    fig = run_figure(read_flight_log(log_path))
    save_figure(fig, out)
    return titles(fig)
