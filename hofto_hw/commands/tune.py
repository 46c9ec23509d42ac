"""``hofto-hw tune PARAMS FILES... -o thresholds.yaml``: choose the momentum observer's gain
and the threshold settings from free-motion recordings with injected contacts.

The files are split into a fitting half and a left-out half (alternating, in the order given).
For every candidate (observer gain, stable at the recordings' rate by
``hofto_hw.observers.stability``; calibration margin; standstill term; sustained residuals) the
thresholds are calibrated on the fitting half; a candidate with any false alarm (episode) on the
left-out half is rejected; among the rest the one detecting most injected pulses on the
left-out half wins (ties: smaller median delay). The winner is re-calibrated on all files and
written with its provenance (files with sha256, settings, the sensitivity table).
"""

from __future__ import annotations

import argparse
import datetime as _dt
import itertools
import sys
from pathlib import Path

import numpy as np

from hofto_hw.commands.args import (
    finite_nonnegative_float,
    finite_positive_float,
    positive_int,
)


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("params", type=Path, help="identified-parameters file")
    parser.add_argument("files", nargs="+", type=Path, metavar="FILE", help="free-motion runs")
    parser.add_argument("-o", "--output", type=Path, required=True, help="thresholds file")
    parser.add_argument("--config", type=Path, help="robot config (default: <robot>.yaml)")
    parser.add_argument("--gains", default="10,20,40", help="momentum gains to try [1/s]")
    parser.add_argument("--margins", default="0.6,0.8,1.0", help="calibration margins to try")
    parser.add_argument("--amplitudes", default="5,10,20", help="pulse sizes [N·m]")
    parser.add_argument(
        "--width", type=finite_positive_float, default=0.4, help="half-sine width [s]"
    )
    parser.add_argument(
        "--pulses", type=positive_int, default=5, help="pulses per joint, size, file"
    )
    parser.add_argument(
        "--debounce", type=finite_nonnegative_float, default=0.03, help="debounce time [s]"
    )
    parser.add_argument("--seed", type=int, default=0)


def _floats(text: str, what: str) -> list[float]:
    from hofto_hw.errors import UserError

    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        values = []
    if not values or not all(np.isfinite(values)) or min(values) < 0:
        raise UserError(f"tune: {what}: expected comma-separated numbers >= 0, got {text!r}")
    return values


def run(args: argparse.Namespace) -> int:
    from hofto_hw.config.collision import CollisionConfig
    from hofto_hw.config.models import ObserverConfig  # noqa: F401  (schema import)
    from hofto_hw.errors import ConfigError, UserError
    from hofto_hw.observers.stability import check_observer
    from hofto_hw.replay.calibrate import calibrate
    from hofto_hw.replay.pulses import inject_pulses
    from hofto_hw.replay.runner import run_monitor, run_observer
    from hofto_hw.replay.session import load_for_replay, observer_for, recording_rate
    from hofto_hw.replay.setup import load_setup, observer_config, sha256_of
    from hofto_hw.replay.thresholds import (
        ObserverThresholds,
        ParametersRef,
        ThresholdsFile,
        write_thresholds,
    )
    from safety.collision import CollisionMonitor

    if len(args.files) < 2:
        raise UserError("tune: give at least 2 free-motion recordings (half are left out)")
    gains = _floats(args.gains, "--gains")
    margins = _floats(args.margins, "--margins")
    amps = _floats(args.amplitudes, "--amplitudes")
    setup = load_setup(args.params, args.config)
    n = setup.model.n
    recs = [load_for_replay(setup, f, None) for f in args.files]
    fit, out = recs[0::2], recs[1::2]
    base_obs = observer_config("momentum", setup)
    rate = min(recording_rate(r) for r in recs)
    say = lambda m: print(f"tune: {m}", file=sys.stderr, flush=True)  # noqa: E731
    stable = []
    for gain in gains:
        try:
            check_observer(
                "momentum", base_obs.model_copy(update={"gain": [gain] * n}), setup.model, rate
            )
            stable.append(gain)
        except ConfigError:
            say(f"gain {gain:g}: unstable at {rate:.4g} Hz, skipped")
    best = None
    for gain, margin, still, sus in itertools.product(
        stable, margins, (False, True), (False, True)
    ):
        obs_cfg = base_obs.model_copy(update={"gain": [gain] * n})
        est_fit = [run_observer(r, observer_for("momentum", obs_cfg, setup, r)) for r in fit]
        template = CollisionConfig(base=[1.0] * n, debounce_time=args.debounce)
        cal = calibrate(
            fit, est_fit, template, margin=margin, terms=(True,) * 4 + (still,), sustain=sus
        )
        rng = np.random.default_rng(args.seed)
        alarms, stats = 0, None
        for r in out:
            est = run_observer(r, observer_for("momentum", obs_cfg, setup, r))
            thr, _, detected = run_monitor(r, est, CollisionMonitor(cal.config))
            alarms += int(np.sum(np.diff(detected.astype(int)) == 1) + detected[0])
            stats = inject_pulses(
                r.t,
                est,
                thr,
                np.full(n, gain),
                args.debounce,
                amps,
                args.pulses,
                rng,
                args.width,
                stats,
            )
        assert stats is not None
        hits = float(stats.hits.sum())
        delay = float(np.nanmedian(stats.median_delay())) if hits else np.inf
        say(
            f"gain {gain:g} margin {margin:g} standstill {still} sustained {sus}: "
            f"{alarms} false alarm(s), {int(hits)}/{int(stats.tries.sum())} pulses, "
            f"median delay {delay:.3f} s"
        )
        key = (hits, -delay)
        if alarms == 0 and (best is None or key > best[0]):
            best = (key, gain, margin, still, sus, stats)
    if best is None:
        raise UserError("tune: every candidate gave false alarms on the left-out runs")
    _, gain, margin, still, sus, stats = best
    obs_cfg = base_obs.model_copy(update={"gain": [gain] * n})
    est_all = [run_observer(r, observer_for("momentum", obs_cfg, setup, r)) for r in recs]
    template = CollisionConfig(base=[1.0] * n, debounce_time=args.debounce)
    cal = calibrate(
        recs, est_all, template, margin=margin, terms=(True,) * 4 + (still,), sustain=sus
    )
    rate_tab, delay_tab = stats.rate, stats.median_delay()
    provenance = {
        "tool": "hofto-hw tune",
        "files": {f.name: sha256_of(f) for f in args.files},
        "left_out": [Path(r.source).name for r in out],
        "settings": {
            "gain": gain,
            "margin": margin,
            "standstill": still,
            "sustained": sus,
            "debounce": args.debounce,
            "amplitudes": amps,
            "width": args.width,
            "pulses": args.pulses,
            "seed": args.seed,
        },
        "sensitivity": {
            f"{a:g}": {"rate": rate_tab[i].tolist(), "median_delay": delay_tab[i].tolist()}
            for i, a in enumerate(amps)
        },
    }
    content = ThresholdsFile(
        robot=setup.config.robot.name,
        parameters=ParametersRef(file=args.params.name, sha256=sha256_of(args.params)),
        created=_dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        margin=margin,
        calibrated_on=[f.name for f in args.files],
        observers={
            "momentum": ObserverThresholds(
                observer=obs_cfg, monitor=cal.config, peak=list(cal.peak), samples=cal.samples
            )
        },
        provenance=provenance,
    )
    write_thresholds(args.output, content)
    print(f"chosen: momentum gain {gain:g}, margin {margin:g}, standstill {still}, sustained {sus}")
    print(f"sensitivity on the left-out runs (rate / median delay [s]), {args.width:g} s pulses:")
    print("  pulse  " + " ".join(f"{'joint ' + str(j + 1):>13}" for j in range(n)))
    for i, a in enumerate(amps):
        cells = " ".join(f"{rate_tab[i, j]:6.2f}/{delay_tab[i, j]:6.3f}" for j in range(n))
        print(f"{a:5g} N·m {cells}")
    print(f"wrote {args.output}")
    return 0
