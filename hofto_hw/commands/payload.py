"""``hofto-hw payload identify PARAMS FILE...``: mass and centre of mass of a load on the tool
frame, with standard deviations; ``-o`` writes the ``payload:`` block for the robot config.
``--inertia`` also fits the inertia about the com (6 values, with std devs) and says whether
the motion made it identifiable; only an identifiable inertia goes into the block (else the
block keeps mass and com of the 4-parameter fit).

``hofto-hw payload set MASS --com X Y Z [--socket S]``: the load a running service's model
carries from now on (``Robot.set_payload``): checked against ``robot.rated_payload``, taken
at standstill only (refused while the arm moves, exit 1).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from hofto_hw.commands.args import (
    HelpFormatter,
    finite_float,
    finite_positive_float,
    output_file,
    refuse_overwrite,
)
from hofto_hw.config.loader import dump_yaml


def configure(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="action", metavar="ACTION", required=True)
    idp = sub.add_parser(
        "identify",
        help="estimate a payload from recordings with it attached",
        formatter_class=HelpFormatter,
    )
    idp.add_argument("params", type=Path, help="identified-parameters file of the arm")
    idp.add_argument("files", nargs="+", metavar="FILE[@FIRST:LAST]")
    idp.add_argument("-o", "--output", type=output_file, help="write the payload: block (YAML)")
    idp.add_argument("--config", type=Path, help="robot config (default: <robot>.yaml)")
    idp.add_argument("--columns", type=Path, help="CSV column map (default: by column count)")
    idp.add_argument(
        "--cutoff", type=finite_positive_float, default=5.0, help="low-pass cut-off [Hz]"
    )
    idp.add_argument(
        "--inertia", action="store_true", help="also fit the inertia about the com (6 values)"
    )
    idp.add_argument("--drop-bad-rows", action="store_true", help="drop corrupt rows")
    idp.add_argument("--json", action="store_true", help="print the estimate as JSON")
    setp = sub.add_parser(
        "set",
        help="the load a running service carries from now on (at standstill)",
        formatter_class=HelpFormatter,
    )
    setp.add_argument("mass", type=finite_float, help="payload mass [kg]")
    setp.add_argument(
        "--com",
        type=finite_float,
        nargs=3,
        metavar=("X", "Y", "Z"),
        default=[0.0, 0.0, 0.0],
        help="centre of mass in the tool frame [m]",
    )
    from hofto_hw.runtime.control_client import add_socket_argument

    add_socket_argument(setp)


def _set(args: argparse.Namespace) -> int:
    from hofto_hw.runtime.control_client import answer, request

    req = {"cmd": "set_payload", "mass": args.mass, "com": list(args.com)}
    return answer(request(args.socket, req))


def run(args: argparse.Namespace) -> int:
    if args.action == "set":
        return _set(args)
    from hofto_hw.identify.inputs import Conditioning, load_samples
    from hofto_hw.identify.payload import identify_payload
    from hofto_hw.outputs import write_atomic
    from hofto_hw.replay.setup import load_setup

    inputs = [args.params, args.config, args.columns, *args.files]
    refuse_overwrite(args.output, inputs, "--output")
    setup = load_setup(args.params, args.config)
    opts = Conditioning(args.cutoff, False, 1, args.drop_bad_rows, trim=False)
    search = [setup.robot_dir, setup.config.robot.urdf.parent]
    gains = setup.parameters.drive_gains
    loaded = load_samples(args.files, args.columns, None, opts, search, gains=gains)
    samples = [s for s, _ in loaded]
    est = identify_payload(setup.model, samples)
    full = identify_payload(setup.model, samples, inertia=True) if args.inertia else None
    block = {"payload": (full if full is not None and full.identifiable else est).as_config()}
    if args.output is not None:
        text = "# written by hofto-hw payload identify from " + ", ".join(
            Path(s.source).name for s, _ in loaded
        )
        body = text + "\n" + dump_yaml(block, sort_keys=False)
        write_atomic(args.output, body, "the payload block")
    if args.json:
        out = {
            "mass": est.mass,
            "mass_std": est.mass_std,
            "com": est.com.tolist(),
            "com_std": est.com_std.tolist(),
            "samples": est.samples,
            "rmse_before": est.rmse_before.tolist(),
            "rmse_after": est.rmse_after.tolist(),
        }
        if full is not None:
            out["with_inertia"] = {
                "mass": full.mass,
                "mass_std": full.mass_std,
                "com": full.com.tolist(),
                "com_std": full.com_std.tolist(),
                "inertia": full.inertia.tolist(),
                "inertia_std": full.inertia_std.tolist(),
                "condition": full.condition,
                "identifiable": full.identifiable,
                "rmse_after": full.rmse_after.tolist(),
            }
        print(json.dumps(out))
        return 0
    print(f"mass {est.mass:.3f} ± {est.mass_std:.3f} kg")
    com = ", ".join(f"{c:.4f} ± {s:.4f}" for c, s in zip(est.com, est.com_std, strict=True))
    print(f"com (tool frame) [m]: {com}")
    print("residual RMSE [N·m] without -> with payload:")
    print(
        "  "
        + " ".join(
            f"{a:.2f}->{b:.2f}" for a, b in zip(est.rmse_before, est.rmse_after, strict=True)
        )
    )
    if full is not None:
        names = ("Ixx", "Ixy", "Iyy", "Ixz", "Iyz", "Izz")
        print(
            f"with the inertia (10 parameters, condition {full.condition:.3g}): mass "
            f"{full.mass:.3f} ± {full.mass_std:.3f} kg"
        )
        print(
            "inertia about the com, tool axes [kg·m²]: "
            + ", ".join(
                f"{k} {v:.4f} ± {e:.4f}"
                for k, v, e in zip(names, full.inertia, full.inertia_std, strict=True)
            )
        )
        print(
            "inertia identifiable: "
            + ("yes (written)" if full.identifiable else "no (not written): std dev or sign")
        )
    return 0
