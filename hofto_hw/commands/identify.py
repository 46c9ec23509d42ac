"""``hofto-hw identify``: fit the dynamic parameters to recordings, write a parameters file.

Example (UR10e, two excitation runs)::

    hofto-hw identify --config configs/ur10e.yaml -o configs/ur10e/parameters.yaml \\
        ur-20_02_12-40sec_12harm.csv@500:4460 ur-20_02_12-50sec_12harm.csv@355:5090
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from hofto_hw.commands.args import (
    add_config,
    add_recording_options,
    finite_nonnegative_float,
    finite_positive_float,
    output_file,
    parse_rows,
    positive_int,
    refuse_overwrite,
    write_failed,
)
from hofto_hw.identify.inputs import Conditioning, load_samples


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("recordings", nargs="+", metavar="FILE[@FIRST:LAST]")
    add_config(parser, default=None, required=True)
    add_recording_options(parser, "rows (1-based, inclusive) for every file")
    parser.add_argument("-o", "--output", type=output_file, required=True, help="parameters file")
    parser.add_argument(
        "--method",
        choices=("ols", "wls", "consistent"),
        default="consistent",
        help="estimate put in the file (default: physically consistent SDP)",
    )
    parser.add_argument(
        "--cutoff", type=finite_positive_float, default=5.0, help="low-pass cut-off [Hz]"
    )
    parser.add_argument("--decimate", type=positive_int, default=1, help="keep every k-th sample")
    parser.add_argument(
        "--smooth-velocity",
        type=finite_nonnegative_float,
        default=0.02,
        help="v_s [rad/s] of the smooth Coulomb sign tanh(qd/v_s); 0 = hard sign",
    )
    parser.add_argument(
        "--stribeck-velocity",
        metavar="VS[,VS...]",
        help="identify a Stribeck term with these Stribeck velocities [rad/s] (one, or n)",
    )
    parser.add_argument(
        "--filter-torque",
        action="store_true",
        help="low-pass the torque too (default: raw torque; filtering smears friction steps)",
    )
    parser.add_argument(
        "--held-velocity",
        type=float,
        help="identify held friction (memory at rest) with this velocity band v_h [rad/s]",
    )
    parser.add_argument(
        "--quadratic", action="store_true", help="identify quadratic friction Fq·qd·|qd|"
    )
    parser.add_argument(
        "--friction-only",
        type=Path,
        metavar="PARAMS",
        help="refresh only the friction of this parameters file (rigid body kept)",
    )
    parser.add_argument(
        "--keep-standstill",
        action="store_true",
        help="keep rest periods at the ends of runs (static holds, held friction)",
    )
    parser.add_argument(
        "--drive-gains",
        action="store_true",
        help="calibrate the current-to-torque gains with --known-load runs, then fit on them",
    )
    parser.add_argument(
        "--known-load",
        action="append",
        metavar="FILE[@FIRST:LAST]:KG",
        help="a run with a load of known mass [kg] on the tool (with --drive-gains; repeatable)",
    )
    parser.add_argument(
        "--gains-from",
        type=Path,
        metavar="PARAMS",
        help="read current with the calibrated drive_gains of this parameters file",
    )
    parser.add_argument("--json", action="store_true", help="print the fit as JSON")


def run(args: argparse.Namespace) -> int:
    from hofto_hw.config.loader import load_config
    from hofto_hw.config.locate import find_config
    from hofto_hw.errors import UserError
    from hofto_hw.identify.drive_gains import parse_known_load
    from hofto_hw.identify.pipeline import identify
    from hofto_hw.model import RobotModel
    from hofto_hw.model.parameters import apply_parameters, read_parameters, write_parameters

    known = [parse_known_load(spec) for spec in args.known_load or []]  # one line each if malformed
    if args.drive_gains and not known:
        raise UserError("identify --drive-gains: give at least one --known-load FILE:KG")
    if known and not args.drive_gains:
        raise UserError("identify: --known-load is used by --drive-gains; add --drive-gains")
    if args.drive_gains and args.gains_from is not None:
        raise UserError("identify: --drive-gains calibrates the gains; drop --gains-from")
    if args.drive_gains and args.friction_only is not None:
        raise UserError("identify: --drive-gains refits the whole model; drop --friction-only")
    config_path = find_config(args.config)
    inputs = [config_path, args.columns, *args.recordings, *(f for f, _ in known)]
    refuse_overwrite(args.output, inputs, "--output")
    cfg = load_config(config_path)
    model = RobotModel.from_config(cfg.robot, apply_parameters=False)
    opts = Conditioning(
        args.cutoff, args.filter_torque, args.decimate, args.drop_bad_rows, not args.keep_standstill
    )
    vs = None
    if args.stribeck_velocity is not None:
        try:
            values = [float(v) for v in args.stribeck_velocity.split(",")]
        except ValueError:
            values = []
        if len(values) not in (1, model.n) or not all(0.0 < v < np.inf for v in values):
            raise UserError(
                f"identify: --stribeck-velocity needs 1 or {model.n} comma-separated finite "
                f"numbers > 0 [rad/s], "
                f"got {args.stribeck_velocity!r}"
            )
        vs = np.broadcast_to(np.asarray(values), (model.n,)).copy()
    search = [cfg.robot.urdf.parent, config_path.parent]

    def say(msg: str) -> None:
        print(f"identify: {msg}", file=sys.stderr, flush=True)

    if args.held_velocity is not None and not (
        np.isfinite(args.held_velocity) and args.held_velocity > 0
    ):
        raise UserError(f"identify: --held-velocity must be > 0 rad/s, got {args.held_velocity}")
    carried = None
    if args.gains_from is not None:
        carried = read_parameters(args.gains_from)
        if carried.drive_gains is None:
            raise UserError(f"{args.gains_from}: drive_gains: missing (no calibrated gains)")
    loaded = load_samples(
        args.recordings,
        args.columns,
        parse_rows(args.rows),
        opts,
        search,
        robot=cfg.robot.name,
        gains=None if carried is None else carried.drive_gains,
    )
    for _s, rec in loaded:
        say(f"loaded {rec.source}: {rec.n_samples} samples, {rec.duration:.1f} s")
    if args.friction_only is not None:
        return _friction_only(args, model, [s for s, _ in loaded], say)
    samples = [s for s, _ in loaded]
    gains = None
    if args.drive_gains:
        gains, samples = _drive_gains(args, cfg, model, known, samples, opts, vs, search, say)
    result = identify(
        model,
        samples,
        args.method,
        args.smooth_velocity,
        progress=say,
        stribeck_velocity=vs,
        held_velocity=args.held_velocity,
        quadratic=args.quadratic,
    )
    if gains is not None:
        result.parameters.drive_gains = gains.gains.copy()
        result.parameters.drive_gains_info = _gains_info(gains, known)
    elif carried is not None:
        result.parameters.drive_gains = carried.drive_gains
        result.parameters.drive_gains_info = dict(
            carried.drive_gains_info, source=args.gains_from.name
        )
    apply_parameters(model, result.parameters, str(args.output))  # refuses a non-SPD M(q)
    try:
        write_parameters(args.output, result.parameters)
    except OSError as exc:
        raise write_failed(args.output, "parameters file", exc) from None
    say(f"wrote {args.output}")
    fit = result.parameters.fit
    if args.json:
        print(
            json.dumps(
                {
                    "method": args.method,
                    "base_parameters": [
                        {
                            "name": b.name,
                            "value": b.value,
                            "std": b.std,
                            "relative_std_percent": b.relative_std_percent,
                        }
                        for b in result.parameters.base
                    ],
                    "rmse": list(map(float, fit["rmse"])),
                    "relative_rmse_percent": list(map(float, fit["relative_rmse_percent"])),
                    "condition_number": float(fit["condition_number"]),
                    "samples": int(fit["samples"]),
                    **(
                        {}
                        if gains is None
                        else {
                            "drive_gains": {
                                **_gains_info(gains, known),
                                "values": gains.gains.tolist(),
                                "free_estimate": gains.free.tolist(),
                                "load_torque_to_noise": gains.load_snr.tolist(),
                                "not_calibrated": gains.weak_joints(model.joint_names),
                            }
                        }
                    ),
                }
            )
        )
        return 0
    if gains is not None:
        _print_gains(gains, model.joint_names)
    print(f"{'base parameter':<28}{'value':>13}{'std':>12}{'rel std %':>11}")
    for b in result.parameters.base:
        rel = b.relative_std_percent
        rel_txt = f"{rel:11.3g}" if rel is not None and np.isfinite(rel) else f"{'-':>11}"
        print(f"{b.name:<28}{b.value:13.5g}{(b.std or 0.0):12.3g}{rel_txt}")
    print()
    print(f"{'joint':<22}{'RMSE [N·m]':>12}{'rel. RMSE %':>13}")
    for j, name in enumerate(model.joint_names):
        print(f"{name:<22}{fit['rmse'][j]:12.3f}{fit['relative_rmse_percent'][j]:13.2f}")
    print(
        f"{fit['samples']} samples, condition number {fit['condition_number']:.4g}, "
        f"method {args.method}"
    )
    return 0


def _friction_only(args: argparse.Namespace, model, samples, say) -> int:
    from hofto_hw.identify.friction_only import refresh_friction
    from hofto_hw.model.parameters import apply_parameters, read_parameters, write_parameters

    old = read_parameters(args.friction_only)
    new = refresh_friction(
        model,
        old,
        samples,
        smooth_velocity=args.smooth_velocity,
        held_velocity=args.held_velocity,
        quadratic=True if args.quadratic else None,
    )
    apply_parameters(model, new, str(args.output))
    write_parameters(args.output, new)
    say(f"wrote {args.output} (rigid body from {args.friction_only})")
    print(f"{'joint':<22}{'Fc old':>9}{'Fc new':>9}{'Fv old':>9}{'Fv new':>9}{'Fh new':>9}")
    for j, name in enumerate(model.joint_names):
        fh = "-" if new.held is None else f"{new.held[j]:.3f}"
        print(
            f"{name:<22}{old.coulomb[j]:9.3f}{new.coulomb[j]:9.3f}"
            f"{old.viscous[j]:9.3f}{new.viscous[j]:9.3f}{fh:>9}"
        )
    return 0


def _drive_gains(args, cfg, model, known, samples, opts, vs, search, say):
    """Calibrate the drive gains on the known-load runs; the runs' torque rescaled to them."""
    from hofto_hw.identify.drive_gains import KnownLoad, estimate_drive_gains
    from hofto_hw.identify.inputs import configured_gains
    from hofto_hw.identify.pipeline import Samples

    files = [f for f, _ in known]
    configured = configured_gains(
        [*args.recordings, *files], args.columns, search, robot=cfg.robot.name
    )
    runs = load_samples(
        files, args.columns, parse_rows(args.rows), opts, search, robot=cfg.robot.name
    )
    loads = [KnownLoad(s, kg) for (s, _), (_, kg) in zip(runs, known, strict=True)]
    est = estimate_drive_gains(
        model,
        samples,
        loads,
        configured,
        smooth_velocity=args.smooth_velocity,
        stribeck_velocity=vs,
        held_velocity=args.held_velocity,
        quadratic=args.quadratic,
        progress=say,
    )
    weak = est.weak_joints(model.joint_names)
    if weak:
        say(f"the known load excites {', '.join(weak)} too weakly: configured gain kept")
    scale = est.scale
    scaled = [Samples(s.q, s.qd, s.qdd, s.tau * scale, s.source) for s in samples]
    return est, scaled


def _gains_info(gains, known) -> dict:
    return {
        "std": [float(v) for v in gains.std],
        "calibrated": [bool(c) for c in gains.calibrated],
        "configured": [float(v) for v in gains.configured],
        "known_loads": [
            {"file": Path(f).name, "mass": float(kg), "com": [float(c) for c in com]}
            for (f, kg), com in zip(known, gains.load_com, strict=True)
        ],
    }


def _print_gains(gains, joints) -> None:
    print(
        f"{'joint':<22}{'configured':>11}{'gain ± std [N·m/A]':>22}{'scale':>8}{'load/noise':>11}"
    )
    for j, name in enumerate(joints):
        status = "" if gains.calibrated[j] else "  kept (weakly excited)"
        print(
            f"{name:<22}{gains.configured[j]:11.4f}{gains.gains[j]:12.4f} ± {gains.std[j]:<7.4f}"
            f"{gains.scale[j]:8.4f}{gains.load_snr[j]:11.2f}{status}"
        )
    weak = gains.weak_joints(joints)
    if weak:
        print(f"not calibrated (configured gain kept): {', '.join(weak)}")
    print()
