"""The run summary (slow path, after the loop): the keys of ``--summary-json`` and the words.

Keys: ticks, rate_hz, overruns, timing_us.{compute,wakeup}.{median,p99,p999,max}, events
[{t, tick, kind, joint, category, detection_delay_ms, stopping_time_ms,
stopping_distance_rad}], observers {name: detection delay [ms] of the scripted collision},
log (path), acceleration (hofto_hw.runtime.acceleration.report: what the tick ran), plus
realtime and clock; with ``run.drag``: drag.{steady_speed_mps, expected_speed_mps,
rest_time_ms, max_speed_mps, drift_mps}; after a taught-path replay (the last trajectory the
loop played): replay.{max_path_error_mm, duration_s, max_jerk_ratio, time_scale, completed};
after a ``mode move --joints``: move.{final_error_rad, duration_s, max_jerk_ratio, completed}.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from drivers.cia402.codes import describe_error_code
from drivers.transport import describe_status
from hofto_hw.runtime.axes import axes_state, axes_text
from safety.stop import EventKind, Fault, kind_name

_CATEGORY_WORDS = {
    0: "category 0 (power removed at once)",
    1: "category 1 (quick-stop ramp, then power removed)",
    2: "category 2 (controlled stop, power kept)",
}


def build_summary(system: Any, log: str | None, realtime: str) -> dict[str, Any]:
    """The summary dictionary of a finished run of ``system`` (hofto_hw.runtime.compose)."""
    tick, loop = system.tick, system.loop
    dt = 1.0 / system.rate_hz
    contact = system.contact
    mon = tick.collision
    observers: dict[str, float | None] = {}
    for r, name in enumerate(system.observer_names):
        first = -1 if mon is None else int(mon.first_tick[r])
        if int(tick.first_detect[r]) >= 0:  # crossed before a reset (the scripted drag's)
            first = int(tick.first_detect[r])
        observers[name] = (
            None
            if contact is None or first < 0
            else round((first * dt - contact.start) * 1000.0, 3)
        )
    ev = tick.stop.events
    stops = {
        int(tick.stop_tick[i]): (float(tick.stop_time[i]), float(tick.stop_distance[i]))
        for i in range(tick.n_stops)
    }
    episode: tuple[float, float] | None = None
    events = []
    for i in range(max(0, ev.count - ev.capacity), ev.count):
        j = i % ev.capacity
        kind, k = int(ev.kind[j]), int(ev.tick[j])
        if kind == EventKind.STANDSTILL:
            continue
        if k in stops:
            episode = stops[k]
        entry: dict[str, Any] = {
            "t": round(k * dt, 6),
            "tick": k,
            "kind": kind_name(kind),
            "joint": int(ev.joint[j]),
            "category": int(ev.category[j]),
            "detection_delay_ms": None,
            "stopping_time_ms": None,
            "stopping_distance_rad": None,
            "value": float(ev.value[j]),
        }
        if kind == Fault.COLLISION and contact is not None and k * dt >= contact.start:
            entry["detection_delay_ms"] = round((k * dt - contact.start) * 1000.0, 3)
        if kind == Fault.DRIVE_FAULT:
            entry["detail"] = "error code (0x603F) " + describe_error_code(int(ev.value[j]))
        elif kind == Fault.BUS_LOSS:
            entry["detail"] = describe_status(int(ev.value[j]))
            history = getattr(system.bus, "node_fault_history", None)  # CANopen: which nodes
            if history is not None and history():
                entry["detail"] += ": " + "; ".join(history())
        elif kind == Fault.BRAKE:
            v = float(ev.value[j])
            entry["detail"] = (
                f"moved {v * 1e3:+.3f} mrad while its brake opened"
                if abs(v) < 1.0
                else "error code (0x603F) " + describe_error_code(int(v))
            )
        elif kind == Fault.STO:
            entry["detail"] = "safe torque off active: the power stage is off"
        if kind < len(Fault) and entry["category"] >= 0 and episode is not None:
            t_stop, d_stop = episode
            if np.isfinite(t_stop):
                entry["stopping_time_ms"] = round(t_stop * 1000.0, 1)
                entry["stopping_distance_rad"] = round(d_stop, 5)
        events.append(entry)
    out = {
        "ticks": int(loop.ticks),
        "rate_hz": float(system.rate_hz),
        "clock": "sim" if system.clock.sim else "real",
        "realtime": realtime,
        "bus": _bus_text(system),
        "acceleration": getattr(system, "acceleration", None),
        "overruns": int(tick.overruns),
        "timing_us": {"compute": loop.compute.summary(), "wakeup": loop.wakeup.summary()},
        "events": events,
        "observers": observers,
        "latched": tick.stop.latched_names(),
        "log": log,
        "axes": axes_state(system),
    }
    script = getattr(system, "drag_script", None)
    if script is not None:
        from hofto_hw.runtime.drag_script import drag_summary

        d = system.cfg.drag
        out["drag"] = drag_summary(script, d.damping, d.standstill_speed)
    pb = tick.playback
    if pb is not None and getattr(pb, "traj", None) is not None:  # not a control-plane stream
        fig = pb.figures(system.model, system.group.q)
        del fig["kind"]
        out[pb.kind] = fig
    return out


def _bus_text(system: Any) -> str:
    """The transport in words; the scripted contact exists on the simulated bus only."""
    bus = system.cfg.bus
    name = str(bus.transport)
    if name == "sim":
        scripted = ", scripted contact" if getattr(system, "contact", None) is not None else ""
        return f"sim (simulated arm{scripted})"
    return f"{name} on {bus.interface} (no scripted contact: that exists on the simulated bus only)"


def format_summary(s: dict[str, Any]) -> str:
    """The same summary in words."""
    lines = [
        f"ran {s['ticks']} ticks at {s['rate_hz']:.0f} Hz ({s['clock']} clock; {s['realtime']}), "
        f"{s['overruns']} missed deadlines",
        f"bus: {s['bus']}",
    ]
    if s.get("acceleration"):
        from hofto_hw.runtime.acceleration import describe

        lines.append(f"tick: {describe(s['acceleration'])}")
    obs = s["observers"]
    if obs:
        shown = ", ".join(
            f"{name} {'not detected' if d is None else f'{d:.1f} ms'}" for name, d in obs.items()
        )
        lines.append(f"detection delay after contact onset: {shown}")
    for e in s["events"]:
        if e["kind"] in ("contact", "reset"):
            continue
        if e["kind"] == "payload":  # four events: the mass (joint -1), the com's x, y, z
            if e["joint"] == -1:
                lines.append(f"t = {e['t']:.3f} s: payload {e['value']:g} kg set")
            continue
        if e["kind"] == "profile":  # joint: the profile's index, value: its collision scale
            lines.append(
                f"t = {e['t']:.3f} s: safety profile switched (collision scale {e['value']:g})"
            )
            continue
        where = f" on joint {e['joint'] + 1}" if e["joint"] >= 0 else ""
        text = f"t = {e['t']:.3f} s: {e['kind'].replace('_', ' ')}{where}"
        if e["category"] >= 0:
            text += f", {_CATEGORY_WORDS[e['category']]}"
        if e.get("detail"):
            text += f" ({e['detail']})"
        if e["detection_delay_ms"] is not None:
            text += f", detected {e['detection_delay_ms']:.1f} ms after onset"
        if e["stopping_time_ms"] is not None:
            text += (
                f"; stopped in {e['stopping_time_ms']:.0f} ms over "
                f"{e['stopping_distance_rad']:.4f} rad"
            )
        lines.append(text)
    if not s["events"]:
        lines.append("no safety events")
    if s.get("axes"):
        lines.append(axes_text(s["axes"]))
    d = s.get("drag")
    if d is not None:
        if d["steady_speed_mps"] is None:
            lines.append("drag: the run ended before the scripted push did")
        else:
            lines.append(
                f"drag: steady tool speed {1e3 * d['steady_speed_mps']:.1f} mm/s "
                f"(F/B_a {1e3 * d['expected_speed_mps']:.1f} mm/s), max "
                f"{1e3 * d['max_speed_mps']:.1f} mm/s, at rest {d['rest_time_ms']:.0f} ms after "
                f"the push, drift {1e3 * (d['drift_mps'] or 0.0):.2f} mm/s with no push"
            )
    r = s.get("replay")
    if r is not None:
        err = r["max_path_error_mm"]
        lines.append(
            f"replay of the taught path: {'' if r['completed'] else 'stopped before the end, '}"
            f"max tool path error {'n/a' if err is None else f'{err:.2f} mm'}, "
            f"{r['duration_s']:.2f} s (move to the start + path at time scale "
            f"{r['time_scale']:.2f}), jerk at {r['max_jerk_ratio']:.3f} of its limit"
        )
    m = s.get("move")
    if m is not None:
        lines.append(
            f"move to joint target: {'reached' if m['completed'] else 'stopped before the end'}"
            f" in {m['duration_s']:.2f} s, final error {m['final_error_rad']:.5f} rad, jerk at "
            f"{m['max_jerk_ratio']:.3f} of its limit"
        )
    c, w = s["timing_us"]["compute"], s["timing_us"]["wakeup"]
    lines.append(
        f"tick compute median {c['median']:.0f} µs, p99 {c['p99']:.0f} µs, max {c['max']:.0f} µs"
    )
    if s["clock"] == "real":
        lines.append(
            f"wake-up latency median {w['median']:.0f} µs, p99 {w['p99']:.0f} µs, "
            f"p99.9 {w['p999']:.0f} µs, max {w['max']:.0f} µs"
        )
    lines.append(f"log: {s['log'] or 'not written'}")
    return "\n".join(lines)
