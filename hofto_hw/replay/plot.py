"""PNG of a replay: estimated external torque per joint with thresholds and episodes."""

from __future__ import annotations

from pathlib import Path

from matplotlib.figure import Figure

from hofto_hw.outputs import atomic_path
from hofto_hw.replay.episodes import Episode
from hofto_hw.replay.runner import ReplayResult


def plot_replay(result: ReplayResult, episodes: list[Episode], path: str | Path) -> Path:
    """Write one panel per joint: tau_ext_hat [N·m], ±threshold, shaded episodes."""
    rec = result.recording
    t = rec.t - rec.t[0]
    n = rec.n_joints
    fig = Figure(figsize=(11, 1.7 * n + 1))  # no pyplot: no global state, no display
    axes = fig.subplots(n, 1, sharex=True, squeeze=False)
    for j in range(n):
        ax = axes[j, 0]
        ax.plot(t, result.tau_ext[:, j], lw=0.8, color="C0", label="estimate")
        if result.threshold is not None:
            ax.plot(t, result.threshold[:, j], lw=0.6, color="C3", label="threshold")
            ax.plot(t, -result.threshold[:, j], lw=0.6, color="C3")
        for ep in episodes:
            ax.axvspan(ep.start - rec.t[0], ep.end - rec.t[0], color="C1", alpha=0.25, lw=0)
        ax.set_ylabel(f"joint {j + 1}\n[N·m]")
        ax.grid(alpha=0.3)
    axes[0, 0].set_title(
        f"{Path(rec.source).name}: {result.observer} estimate, {len(episodes)} contact episode(s)"
    )
    axes[0, 0].legend(loc="upper right", fontsize=7)
    axes[-1, 0].set_xlabel("time since start [s]")
    fig.tight_layout()
    path = Path(path)
    with atomic_path(path, "plot") as tmp:  # exactly at path, whatever its suffix
        fig.savefig(tmp, dpi=90, format="png")
    return path
