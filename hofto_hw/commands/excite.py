"""``hofto-hw excite``: design an optimized Fourier excitation trajectory.

Writes a CSV (header ``t,q1..qn,qd1..qdn,qdd1..qddn``; s, rad, rad/s, rad/s²) sampled at
``--rate`` over ``--cycles`` periods, starting and ending at rest, and a PNG of q, qd, qdd;
prints the achieved condition number of the stacked base regressor.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from hofto_hw.commands.args import (
    add_config,
    at_most,
    finite_positive_float,
    output_file,
    positive_int,
    refuse_overwrite,
    write_failed,
)
from hofto_hw.outputs import atomic_path

MAX_SAMPLES = 10e6  # rows of the trajectory file (~1 GB of CSV)
DEFAULT_ACCELERATION = 5.0  # rad/s², when neither the config nor --max-acceleration gives one


def configure(parser: argparse.ArgumentParser) -> None:
    add_config(parser, default=None, required=True)
    parser.add_argument("-o", "--output", type=output_file, required=True, help="trajectory CSV")
    parser.add_argument("--plot", type=output_file, help="PNG (default: OUTPUT with .png)")
    parser.add_argument(
        "--harmonics", type=at_most(50, positive_int), default=5, help="Fourier harmonics L"
    )
    parser.add_argument("--period", type=at_most(600, unit=" s"), default=10.0, help="period [s]")
    parser.add_argument(
        "--cycles", type=at_most(100, positive_int), default=1, help="periods in the file"
    )
    parser.add_argument(
        "--rate",
        type=at_most(10_000, unit=" Hz"),
        default=100.0,
        help="sample rate of the CSV [Hz]",
    )
    parser.add_argument(
        "--range",
        type=finite_positive_float,
        default=1.0,
        help="max excursion from home per joint [rad] (within the position limits)",
    )
    parser.add_argument(
        "--velocity-scale",
        type=at_most(1.0),
        default=0.8,
        help="fraction of the velocity limits",
    )
    parser.add_argument(
        "--max-acceleration", type=finite_positive_float, help="[rad/s²] for every joint"
    )
    parser.add_argument(
        "--iterations", type=at_most(10_000, positive_int), default=100, help="SLSQP iterations"
    )
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--no-torque-limits", action="store_true", help="ignore torque limits")


def run(args: argparse.Namespace) -> int:
    from hofto_hw.config.loader import load_config
    from hofto_hw.config.locate import find_config
    from hofto_hw.errors import UserError
    from hofto_hw.identify.base_params import find_base_parameters
    from hofto_hw.identify.excitation import ExcitationLimits, design_excitation
    from hofto_hw.identify.pipeline import nominal_theta
    from hofto_hw.identify.regressor import Regressor
    from hofto_hw.model import RobotModel

    samples = args.cycles * args.period * args.rate
    if samples > MAX_SAMPLES:
        raise UserError(
            f"--cycles x --period x --rate = {samples:.3g} samples; at most {MAX_SAMPLES:g} "
            "(an excitation file a person can load)"
        )
    config_path = find_config(args.config)
    png = args.plot or args.output.with_suffix(".png")
    if png == args.output:
        raise UserError(f"--plot {png}: is the trajectory file (--output); give another name")
    for option, out in (("--output", args.output), ("--plot", png)):
        refuse_overwrite(out, [config_path], option)
    cfg = load_config(config_path)
    model = RobotModel.from_config(cfg.robot)
    lim = model.limits
    lo = np.maximum(lim.position_lower, model.home - args.range)
    hi = np.minimum(lim.position_upper, model.home + args.range)
    vel = np.where(np.isfinite(lim.velocity), lim.velocity, 2.0) * args.velocity_scale
    acc = lim.acceleration.copy()
    if args.max_acceleration is not None:
        acc[:] = args.max_acceleration
    acc[~np.isfinite(acc)] = DEFAULT_ACCELERATION
    limits = ExcitationLimits(lo, hi, vel, acc, lim.torque.copy())
    reg = Regressor(model.pin_model, model.friction.smooth_velocity or 0.02)
    base = find_base_parameters(reg, model.joint_names)

    def progress(it: int, cond: float) -> None:
        print(f"excite: iteration {it}: condition number {cond:.4g}", file=sys.stderr, flush=True)

    traj, cond = design_excitation(
        reg,
        base,
        limits,
        harmonics=args.harmonics,
        period=args.period,
        max_iter=args.iterations,
        seed=args.seed,
        nominal=None if args.no_torque_limits else nominal_theta(model),
        progress=progress,
    )
    t = np.arange(0.0, args.cycles * args.period + 0.5 / args.rate, 1.0 / args.rate)
    q, qd, qdd = traj.evaluate(t)
    n = model.n
    header = ",".join(
        ["t"]
        + [f"q{j + 1}" for j in range(n)]
        + [f"qd{j + 1}" for j in range(n)]
        + [f"qdd{j + 1}" for j in range(n)]
    )
    print(
        f"condition number {cond:.4g} ({base.p} base parameters, {args.harmonics} harmonics, "
        f"period {args.period:g} s)",
        flush=True,
    )
    try:
        with atomic_path(args.output, "trajectory") as tmp:
            np.savetxt(
                tmp,
                np.column_stack([t, q, qd, qdd]),
                delimiter=",",
                header=header,
                comments="",
                fmt="%.9g",
            )
    except OSError as exc:
        raise write_failed(args.output, "trajectory", exc) from None
    try:
        _plot(png, t, q, qd, qdd, model.joint_names, cond)
    except OSError as exc:
        raise write_failed(png, "figure", exc) from None
    print(f"wrote {args.output} ({t.size} samples) and {png}")
    return 0


def _plot(
    path: Path,
    t: np.ndarray,
    q: np.ndarray,
    qd: np.ndarray,
    qdd: np.ndarray,
    names: list[str],
    cond: float,
) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(3, 1, figsize=(10, 8), sharex=True)
    for ax, data, label in zip(
        axes, (q, qd, qdd), ("q [rad]", "qd [rad/s]", "qdd [rad/s²]"), strict=True
    ):
        for j, name in enumerate(names):
            ax.plot(t, data[:, j], lw=0.9, label=name)
        ax.set_ylabel(label)
        ax.grid(True, lw=0.3)
    axes[0].legend(fontsize=7, ncol=3)
    axes[-1].set_xlabel("t [s]")
    fig.suptitle(f"excitation trajectory, condition number {cond:.4g}")
    fig.tight_layout()
    try:
        with atomic_path(path, "figure") as tmp:  # exactly at path, whatever its suffix
            fig.savefig(tmp, dpi=100, format="png")
    finally:
        plt.close(fig)
