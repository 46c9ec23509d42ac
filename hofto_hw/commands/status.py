"""``hofto-hw status``: state, latched faults, timing, safe torque off and holding brake per
axis, and log file of the running service,
and the taught-path recording and last trajectory played (``mode drag --record``,
``mode replay``, ``mode move --joints``)."""

from __future__ import annotations

import argparse
import json

from hofto_hw.errors import UserError
from hofto_hw.runtime.control_client import add_socket_argument, answer, request


def configure(parser: argparse.ArgumentParser) -> None:
    add_socket_argument(parser)
    parser.add_argument("--json", action="store_true", help="print the raw JSON")


def run(args: argparse.Namespace) -> int:
    s = request(args.socket, "status")
    if args.json:
        print(json.dumps(s, indent=2))
        return 0
    if not s.get("ok"):
        return answer(s)
    try:
        _print(s)
    except (KeyError, TypeError, ValueError, AttributeError, IndexError) as exc:
        raise UserError(
            f"{args.socket}: malformed status answer: {type(exc).__name__}: {exc}"
        ) from None
    return 0


def _print(s: dict) -> None:
    c = s["timing_us"]["compute"]
    w = s["timing_us"]["wakeup"]
    print(f"state: {s['state']} (mode {s['mode']}), {s['ticks']} ticks, {s['overruns']} missed")
    faults = ", ".join(s["faults"]) or "none"
    still = f" (cause present: {', '.join(s['persisting'])})" if s["persisting"] else ""
    print(f"faults: {faults}{still}; stop category {s['category'] if s['category'] >= 0 else '-'}")
    print(
        f"compute median {c['median']:.0f} µs, p99 {c['p99']:.0f} µs; "
        f"wake-up median {w['median']:.0f} µs, p99 {w['p99']:.0f} µs"
    )
    prof = s.get("profile")
    if prof:
        print(
            f"safety profile: {prof['name']} (collision thresholds x{prof['collision_scale']:g}, "
            f"speed x{prof['speed_scale']:g}; drag mass x{prof.get('drag_mass_scale', 1.0):g}, "
            f"damping x{prof.get('drag_damping_scale', 1.0):g}, "
            f"speed x{prof.get('drag_speed_scale', 1.0):g})"
        )
    load = s.get("payload")
    if load:
        com = ", ".join(f"{v:g}" for v in load["com"])
        print(f"payload: {load['mass']:g} kg at com [{com}] m (tool frame)")
    if s.get("holder"):
        print(f"motion held by {s['holder']}")
    if s.get("axes"):
        from hofto_hw.runtime.axes import axes_text

        print(axes_text(s["axes"]))
    print(f"log: {s['log'] or 'not yet written'}")
    if s.get("acceleration"):
        from hofto_hw.runtime.acceleration import describe

        print(f"tick: {describe(s['acceleration'])}")
    rec = s.get("teach")
    if rec:
        print(f"taught path: {rec['state']}, {rec['samples']} samples -> {rec['file']}")
        if rec["message"]:
            print(f"  {rec['message']}")
    pb = s.get("playback")
    if pb:
        what = "replay of " + pb["file"] if pb["kind"] == "replay" else "move to joint target"
        done = "done" if pb["completed"] else f"{100.0 * pb['progress']:.0f} %"
        print(f"last trajectory: {what}, {pb['duration_s']:.2f} s, {done}")
