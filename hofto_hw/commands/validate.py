"""``hofto-hw validate``: torque prediction errors of a parameters file on recordings.

Prints per-joint RMSE [N·m] and relative RMSE (100·||e||/||tau|| [%]) for each file and
over all of them, writes a measured-vs-predicted PNG (the paper's Fig. 2), or with ``--json``
prints the same numbers as JSON. ``--compare OTHER`` evaluates a second parameters file side
by side. The config is found from the file's robot name (``<robot>.yaml`` next to it or one
folder up) unless ``--config`` is given; CSV column maps likewise (``columns_<k>.yaml``).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from hofto_hw.commands.args import (
    add_config,
    add_recording_options,
    ensure_default_folder,
    finite_positive_float,
    output_file,
    parse_rows,
    refuse_overwrite,
    write_failed,
)
from hofto_hw.identify.inputs import Conditioning, load_samples

if TYPE_CHECKING:
    from hofto_hw.config.models import SystemConfig
    from hofto_hw.model.robot import RobotModel


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("parameters", type=Path, metavar="PARAMS", help="parameters file")
    parser.add_argument("recordings", nargs="+", metavar="FILE[@FIRST:LAST]")
    add_config(parser, default=None)
    add_recording_options(parser, "rows (1-based, inclusive) for every file")
    parser.add_argument("--compare", type=Path, metavar="PARAMS2", help="second file to compare")
    parser.add_argument(
        "--cutoff", type=finite_positive_float, default=5.0, help="velocity low-pass [Hz]"
    )
    parser.add_argument(
        "--filter-torque",
        action="store_true",
        help="low-pass the measured torque too (default: compare with the raw torque)",
    )
    parser.add_argument(
        "--plot",
        type=output_file,
        metavar="PNG",
        help="PNG to write (default: out/validate_<PARAMS stem>.png)",
    )
    parser.add_argument("--no-plot", action="store_true", help="write no figure")
    parser.add_argument("--json", action="store_true", help="print the numbers as JSON")


def _model(params: Path, config: str | None) -> tuple[RobotModel, SystemConfig, np.ndarray | None]:
    from hofto_hw.config.loader import load_config
    from hofto_hw.config.locate import find_config
    from hofto_hw.model import RobotModel
    from hofto_hw.model.parameters import apply_parameters, read_parameters

    pf = read_parameters(params)
    cfg_path = find_config(config, pf.robot, params.parent)
    cfg = load_config(cfg_path)
    model = RobotModel.from_config(cfg.robot, apply_parameters=False)
    apply_parameters(model, pf, str(params))
    return model, cfg, pf.drive_gains


def run(args: argparse.Namespace) -> int:
    from hofto_hw.identify.validation import errors, plot_fit, predict

    png = None if args.no_plot else args.plot
    if png is None and not args.no_plot:
        png = Path("out") / f"validate_{args.parameters.stem}.png"
    inputs = [args.parameters, args.compare, args.config, args.columns, *args.recordings]
    refuse_overwrite(png, inputs, "--plot")
    model, cfg, gains = _model(args.parameters, args.config)
    models = {args.parameters.stem: model}
    model_gains = {args.parameters.stem: gains}
    if args.compare is not None:
        other, _, other_gains = _model(args.compare, args.config)
        models[args.compare.stem] = other
        model_gains[args.compare.stem] = other_gains
    opts = Conditioning(args.cutoff, args.filter_torque, 1, args.drop_bad_rows)
    search = [args.parameters.parent, cfg.robot.urdf.parent]
    rows = parse_rows(args.rows)
    # each model against the torque on its own drive gains (a calibrated model's scale)
    by_gains: dict = {}
    for g in model_gains.values():
        key = None if g is None else tuple(g)
        if key not in by_gains:
            by_gains[key] = load_samples(
                args.recordings, args.columns, rows, opts, search, robot=cfg.robot.name, gains=g
            )
    loaded = by_gains[None if gains is None else tuple(gains)]

    report: dict = {"files": [], "models": list(models)}
    taus: dict = {k: [] for k in models}
    preds: dict = {k: [] for k in models}
    for i, (_s, rec) in enumerate(loaded):
        entry = {"file": rec.source, "samples": rec.n_samples, "models": {}}
        for name, m in models.items():
            g = model_gains[name]
            sm = by_gains[None if g is None else tuple(g)][i][0]
            tau_hat = predict(m, sm.q, sm.qd, sm.qdd)
            preds[name].append(tau_hat)
            taus[name].append(sm.tau)
            entry["models"][name] = errors(sm.tau, tau_hat).as_dict()
        report["files"].append(entry)
    report["overall"] = {
        name: errors(np.vstack(taus[name]), np.vstack(p)).as_dict() for name, p in preds.items()
    }
    if png is not None:
        report["plot"] = str(png)
    # numbers first: a figure that cannot be written must not cost the user the results
    if args.json:
        print(json.dumps(report))
    else:
        _print(report, model.joint_names)
    if png is not None:
        if args.plot is None:
            ensure_default_folder(png)
        s0, rec0 = loaded[0]
        try:
            plot_fit(
                png,
                rec0.t - rec0.t[0],
                s0.tau,
                {k: v[0] for k, v in preds.items()},
                model.joint_names,
                title=f"{Path(rec0.source).name}: measured vs predicted",
            )
        except OSError as exc:
            raise write_failed(png, "figure", exc) from None
        if not args.json:
            print(f"figure: {png}")
    return 0


def _print(report: dict, joints: list[str]) -> None:
    names = report["models"]
    head = "".join(f"{'RMSE ' + n[:14]:>22}{'rel %':>8}" for n in names)
    for entry in [*report["files"], {"file": "all files", "models": report["overall"]}]:
        print(f"{Path(entry['file']).name}")
        print(f"  {'joint':<22}{head}")
        for j, joint in enumerate(joints):
            row = "".join(
                f"{entry['models'][n]['rmse'][j]:22.3f}"
                f"{entry['models'][n]['relative_rmse_percent'][j]:8.2f}"
                for n in names
            )
            print(f"  {joint:<22}{row}")
