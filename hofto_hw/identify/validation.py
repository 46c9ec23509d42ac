"""Torque prediction errors of a model on recordings, and the measured-vs-predicted figure.

Figure of merit of the UR10e dataset's authors: relative RMSE per joint
``100·||tau − tau_hat||₂ / ||tau||₂`` [%] over a whole file; plus the plain RMSE [N·m].
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from hofto_hw.outputs import atomic_path

if TYPE_CHECKING:
    from hofto_hw.model.robot import RobotModel


@dataclass
class Errors:
    """Per-joint RMSE [N·m] and relative RMSE [%], arrays (n,), over ``samples`` samples."""

    rmse: np.ndarray
    relative_percent: np.ndarray
    samples: int

    def as_dict(self) -> dict[str, list[float] | int]:
        return {
            "rmse": [float(v) for v in self.rmse],
            "relative_rmse_percent": [float(v) for v in self.relative_percent],
            "samples": self.samples,
        }


def predict(model: RobotModel, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray) -> np.ndarray:
    """tau_hat = M·qdd + C·qd + g + f for every sample; inputs and output (N, n)."""
    out = np.empty_like(np.asarray(q, dtype=float))
    data = model.create_data()
    for k in range(out.shape[0]):
        data.inverse_dynamics(q[k], qd[k], qdd[k], out=out[k])
    return out


def errors(tau: np.ndarray, tau_hat: np.ndarray) -> Errors:
    """Errors of ``tau_hat`` against measured ``tau``, both (N, n) [N·m]."""
    e = tau - tau_hat
    norm_e = np.linalg.norm(e, axis=0)
    norm_t = np.linalg.norm(tau, axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        rel = np.where(norm_t > 0.0, 100.0 * norm_e / norm_t, np.inf)
    return Errors(norm_e / np.sqrt(tau.shape[0]), rel, int(tau.shape[0]))


def plot_fit(
    path: str | Path,
    t: np.ndarray,
    tau: np.ndarray,
    predictions: dict[str, np.ndarray],
    joint_names: list[str],
    title: str = "",
) -> None:
    """Measured vs predicted torque per joint, with the error of the first prediction (the
    paper's Fig. 2 layout: measured blue, predicted red, error green). Writes a PNG into an
    existing folder; raises OSError when it cannot."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = tau.shape[1]
    fig, axes = plt.subplots((n + 1) // 2, 2, figsize=(12, 2.4 * ((n + 1) // 2)), sharex=True)
    colors = ["tab:red", "tab:orange", "tab:purple"]
    first = next(iter(predictions.values()))
    for j, ax in enumerate(axes.ravel()[:n]):
        ax.plot(t, tau[:, j], color="tab:blue", lw=0.8, label="measured")
        for (label, pred), c in zip(predictions.items(), colors, strict=False):
            ax.plot(t, pred[:, j], color=c, lw=0.8, label=label)
        ax.plot(t, tau[:, j] - first[:, j], color="tab:green", lw=0.6, label="error")
        ax.set_ylabel(f"{joint_names[j]}\n[N·m]", fontsize=8)
        ax.grid(True, lw=0.3)
    for ax in axes.ravel()[n:]:
        ax.set_visible(False)
    axes.ravel()[0].legend(fontsize=7, loc="upper right")
    for ax in axes.ravel()[-2:]:
        ax.set_xlabel("t [s]")
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    try:
        with atomic_path(path, "figure") as tmp:  # exactly at path, whatever its suffix
            fig.savefig(tmp, dpi=110, format="png")
    finally:
        plt.close(fig)
