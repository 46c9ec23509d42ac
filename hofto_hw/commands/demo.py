"""``hofto-hw demo``: the paper's Table II experiment on the simulated ER3A-class arm.

Prints Table II's layout (Offset / MA / RMS per joint for HOFTO, ESO, DOB) twice — with the
paper's gains and with ESO/DOB matched to HOFTO's measured bandwidth — with the HOFTO/ESO and
HOFTO/DOB RMS ratios next to the paper's, and writes a Fig. 4-style PNG. ``--json`` prints
the same figures as JSON for scripts.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from hofto_hw.commands.args import (
    add_config,
    at_most,
    ensure_default_folder,
    output_file,
    write_failed,
)
from hofto_hw.outputs import atomic_path

DEFAULT_CONFIG = "er3a"  # the simulated ER3A-class arm of the paper (configs/er3a.yaml)
DEFAULT_PLOT = Path("out/demo_fig4.png")  # ours: its folder is created
TABLE_OBSERVERS = ("hofto", "eso", "dob")


def configure(parser: argparse.ArgumentParser) -> None:
    add_config(parser, default=DEFAULT_CONFIG)
    parser.add_argument(
        "--duration", type=at_most(3600, unit=" s"), default=20.0, help="simulated seconds (>= 5)"
    )
    parser.add_argument("--json", action="store_true", help="print the figures as JSON only")
    parser.add_argument("--plot", type=output_file, default=DEFAULT_PLOT, help="Fig. 4-style PNG")
    parser.add_argument("--no-plot", action="store_true", help="do not write the PNG")


def run(args: argparse.Namespace) -> int:
    from hofto_hw.commands.backend import observer_backend
    from hofto_hw.config import load_config
    from hofto_hw.config.locate import find_config
    from hofto_hw.errors import ConfigError
    from hofto_hw.experiments import table2
    from hofto_hw.model import RobotModel
    from hofto_hw.observers import make_observer
    from hofto_hw.observers.stability import check_observer

    if args.duration < 5.0:
        raise ConfigError(f"--duration: at least 5 s are needed, got {args.duration}")
    config_path = find_config(args.config)
    if not args.no_plot and args.plot == DEFAULT_PLOT:
        ensure_default_folder(args.plot)
    cfg = load_config(config_path)
    missing = [name for name in TABLE_OBSERVERS if name not in cfg.observers]
    if missing:
        raise ConfigError(f"{config_path}: observers: the demo needs {', '.join(missing)}")
    say = (lambda *_: None) if args.json else (lambda msg: print(msg, file=sys.stderr))
    started = time.perf_counter()
    model = RobotModel.from_config(cfg.robot)
    for name, ocfg in cfg.observers.items():  # refuse gains unstable at the loop rate
        try:
            check_observer(name, ocfg, model, cfg.loop.rate_hz)
        except ConfigError as exc:
            raise ConfigError(f"{args.config}: {exc} (rate: loop.rate_hz)") from None
    backend = observer_backend()
    say(f"simulating {args.duration:.0f} s of the tracking task at {cfg.loop.rate_hz:.0f} Hz ...")
    samples = table2.simulate(cfg, model, args.duration)
    say("running the observers on the same samples ...")
    paper = table2.compare(
        "paper gains",
        {name: make_observer(ocfg, model, backend=backend) for name, ocfg in cfg.observers.items()},
        samples,
    )
    say("measuring HOFTO's bandwidth and matching ESO and DOB to it ...")
    matched_obs, fc, amplitude = table2.matched_observers(cfg, model, samples, backend=backend)
    matched = table2.compare("matched bandwidth", matched_obs, samples)
    elapsed = time.perf_counter() - started

    report = _report(cfg, samples, paper, matched, fc, amplitude, elapsed)
    if args.json:
        print(json.dumps(report, indent=2))
    else:
        print(_format_table(paper, "with the paper's gains (DOB cutoff 20 rad/s: ours)"))
        print()
        print(
            _format_table(
                matched,
                "with ESO and DOB matched to HOFTO's -3 dB bandwidth "
                f"({', '.join(f'{f:.2f}' for f in fc)} Hz)",
            )
        )
        others = [k for k in paper.indices if k not in TABLE_OBSERVERS]
        if others:
            print()
            print("Other observers, RMS error [N·m] per joint (paper gains config):")
            for name in others:
                rms = paper.indices[name]["rms"]
                print(f"  {name:<9}" + "".join(f"{v:9.3f}" for v in rms))
        rms = np.sqrt((samples.tau_ext**2).mean(axis=0))
        print(f"  {'|tau_ext|':<9}" + "".join(f"{v:9.3f}" for v in rms) + "   (RMS of the truth)")
        print(f"\nsimulated {samples.t[-1]:.1f} s in {elapsed:.1f} s")
    if not args.no_plot:
        try:
            _plot(samples, paper, args.plot)
        except OSError as exc:
            raise write_failed(args.plot, "figure", exc) from None
        say(f"wrote {args.plot}")
    return 0


def _report(cfg, samples, paper, matched, fc, amplitude, elapsed) -> dict:
    from hofto_hw.experiments.table2 import PAPER_TABLE2, paper_ratios

    def block(comp) -> dict:
        out = {
            name: {k: [float(x) for x in v] for k, v in idx.items()}
            for name, idx in comp.indices.items()
        }
        h = comp.indices["hofto"]["rms"]
        ratios = {
            "hofto/eso": [float(x) for x in h / comp.indices["eso"]["rms"]],
            "hofto/dob": [float(x) for x in h / comp.indices["dob"]["rms"]],
        }
        return {"indices": out, "rms_ratios": ratios}

    return {
        "robot": cfg.robot.name,
        "rate_hz": cfg.loop.rate_hz,
        "duration_s": float(samples.t[-1]),
        "units": "N·m",
        "tau_ext_rms": [float(x) for x in np.sqrt((samples.tau_ext**2).mean(axis=0))],
        "paper_gains": block(paper),
        "matched_bandwidth": {
            **block(matched),
            "bandwidth_hz": [float(x) for x in fc],
            "x3_amplitude": [float(x) for x in amplitude],
        },
        "paper_table2": PAPER_TABLE2,
        "paper_rms_ratios": paper_ratios(),
        "elapsed_s": elapsed,
    }


def _format_table(comp, title: str) -> str:
    from hofto_hw.experiments.table2 import paper_ratios

    pr = paper_ratios()
    lines = [f"Table II layout: estimation error [N·m], simulated arm, {title}", ""]
    n = len(comp.indices["hofto"]["rms"])
    for first in range(0, n, 3):
        joints = range(first, min(first + 3, n))
        head = " " * 14 + "".join(f"{'tau_e' + str(j + 1):^29}" for j in joints)
        sub = " " * 14 + "".join(f"{'Offset':>9}{'MA':>10}{'RMS':>10}" for _ in joints)
        lines += [head, sub]
        for name in TABLE_OBSERVERS:
            idx = comp.indices[name]
            row = f"{name.upper():<14}" + "".join(
                f"{idx['offset'][j]:9.4f}{idx['ma'][j]:10.4f}{idx['rms'][j]:10.4f}" for j in joints
            )
            lines.append(row)
        for other, key in (("eso", "hofto/eso"), ("dob", "hofto/dob")):
            ours = comp.indices["hofto"]["rms"] / comp.indices[other]["rms"]
            row = f"{key + ' RMS':<14}" + "".join(
                f"{'ratio':>9}{ours[j]:10.3f}{'(' + format(pr[key][j], '.3f') + ')':>10}"
                for j in joints
            )
            lines.append(row)
        lines.append("")
    lines.append(
        "ratios: ours, then the paper's Table II in parentheses; lower is better for HOFTO"
    )
    return "\n".join(lines)


def _plot(samples, comp, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(3, 2, figsize=(12, 9), sharex=True)
    colours = {"hofto": "tab:red", "eso": "gold", "dob": "tab:purple"}
    for j, ax in enumerate(axes.T.ravel()):
        ax.plot(samples.t, samples.tau_ext[:, j], color="tab:blue", lw=1.6, label="true")
        for name in TABLE_OBSERVERS:
            ax.plot(
                samples.t,
                comp.estimates[name][:, j],
                color=colours[name],
                lw=0.9,
                label=name.upper(),
            )
        ax.set_title(f"({'abcdef'[j]}) joint {j + 1}")
        ax.set_ylabel("tau_ext [N·m]")
        ax.grid(alpha=0.3)
    for ax in axes[-1]:
        ax.set_xlabel("t [s]")
    axes[0, 0].legend(loc="upper right", fontsize=8)
    fig.suptitle("External torque estimates, paper's gains (cf. Fig. 4 of Han et al. 2022)")
    fig.tight_layout()
    try:
        with atomic_path(path, "figure") as tmp:  # exactly at path, whatever its suffix
            fig.savefig(tmp, dpi=110, format="png")
    finally:
        plt.close(fig)
