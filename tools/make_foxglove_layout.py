"""Write docs/foxglove/hofto-hw.json, the Foxglove layout for flight logs and the live view,
with foxglove-sdk's layout types (foxglove.layouts: Foxglove's own panel schema).

    python tools/make_foxglove_layout.py            # rewrite the shipped layout
    python tools/make_foxglove_layout.py --check    # exit 1 if the shipped one differs

Tabs: "arm" (the 3D arm from /robot_description and /tf, joint positions and velocities, the
tool wrench, controller mode and faults, safety events), "torques" (per joint the detector's
estimated external torque against the contact and collision thresholds of /safety/thresholds),
"loop" (compute and wake-up time per tick, /diagnostics). Topics are the flight recorder's
(docs/recording.md); the detector is the shipped configs' (``hofto``).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import foxglove.layouts as fl

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "docs" / "foxglove" / "hofto-hw.json"
JOINTS = 6
DETECTOR = "hofto"
BASE_FRAME = "base_link"


def _plot(title: str, series: list[tuple[str, str]], **kw: object) -> fl.PlotPanel:
    return fl.PlotPanel(
        title=title,
        config=fl.PlotConfig(
            paths=[
                fl.PlotSeries(value=v, label=label, timestamp_method="receiveTime")
                for v, label in series
            ],
            show_legend=True,
            legend_display="floating",
            is_synced=True,
            **kw,  # type: ignore[arg-type]
        ),
    )


def _column(*panels: object, proportions: list[float] | None = None) -> fl.SplitContainer:
    props = proportions or [1.0] * len(panels)
    return fl.SplitContainer(
        direction="column",
        items=[fl.SplitItem(proportion=p, content=c) for p, c in zip(props, panels, strict=True)],  # type: ignore[arg-type]
    )


def _row(*panels: object, proportions: list[float] | None = None) -> fl.SplitContainer:
    props = proportions or [1.0] * len(panels)
    return fl.SplitContainer(
        direction="row",
        items=[fl.SplitItem(proportion=p, content=c) for p, c in zip(props, panels, strict=True)],  # type: ignore[arg-type]
    )


def arm_tab() -> fl.SplitContainer:
    three_d = fl.ThreeDeePanel(
        title="arm (URDF from /robot_description, links from /tf)",
        config=fl.ThreeDeeConfig(
            follow_tf=BASE_FRAME,
            layers={
                "urdf": fl.BaseRendererUrdfLayerSettings(
                    layer_id="foxglove.Urdf",
                    label="arm",
                    source_type="topic",
                    topic="/robot_description",
                    control_mode="transforms",
                    show_axis=True,
                    axis_scale=0.3,
                ),
                "grid": fl.BaseRendererGridLayerSettings(layer_id="foxglove.Grid", label="grid"),
            },
            topics={
                "/tool/wrench_estimate": fl.BaseRendererBaseSettings(visible=True),
            },
        ),
    )
    j = range(JOINTS)
    q = _plot("joint positions [rad]", [(f"/joint_states.position[{i}]", f"q{i + 1}") for i in j])
    qd = _plot(
        "joint velocities [rad/s]", [(f"/joint_states.velocity[{i}]", f"qd{i + 1}") for i in j]
    )
    axes = [f"force.{a}" for a in "xyz"] + [f"torque.{a}" for a in "xyz"]
    wrench = _plot(
        "tool wrench estimate [N, N·m] (frame tool0_aligned: base axes at the tool)",
        [(f"/tool/wrench_estimate.wrench.{a}", a) for a in axes],
    )
    mode = fl.StateTransitionsPanel(
        title="controller mode and latched faults",
        config=fl.StateTransitionsConfig(
            paths=[
                fl.StateTransitionsSeries(value="/loop/status.mode", label="mode"),
                fl.StateTransitionsSeries(value="/loop/status.faults", label="faults"),
            ],
            is_synced=True,
        ),
    )
    events = fl.RawMessagesPanel(
        title="safety events", config=fl.RawMessagesConfig(topic_path="/safety/events")
    )
    left = _column(three_d, mode, events, proportions=[3.0, 1.0, 1.5])
    right = _column(q, qd, wrench)
    return _row(left, right, proportions=[1.0, 1.2])


def torque_tab() -> fl.SplitContainer:
    panels = []
    for i in range(JOINTS):
        panels.append(
            _plot(
                f"joint {i + 1}: {DETECTOR} estimate vs thresholds [N·m] (|estimate| is judged)",
                [
                    (f"/observers/{DETECTOR}/tau_ext.effort[{i}]", "estimate"),
                    (f"/safety/thresholds.contact[{i}]", "contact"),
                    (f"/safety/thresholds.collision[{i}]", "collision"),
                ],
            )
        )
    return _row(_column(*panels[0::2]), _column(*panels[1::2]))


def loop_tab() -> fl.SplitContainer:
    timing = _plot(
        "loop timing per tick [µs]",
        [("/loop/status.compute_us", "compute"), ("/loop/status.wakeup_us", "wake-up latency")],
    )
    diags = fl.DiagnosticsSummaryPanel(
        title="diagnostics (loop p99, bus, recorder)",
        config=fl.DiagnosticsSummaryConfig(topic_to_render="/diagnostics"),
    )
    return _column(timing, diags)


def layout() -> fl.Layout:
    return fl.Layout(
        content=fl.TabContainer(
            tabs=[
                fl.TabItem(title="arm", content=arm_tab()),
                fl.TabItem(title="torques vs thresholds", content=torque_tab()),
                fl.TabItem(title="loop", content=loop_tab()),
            ]
        )
    )


def layout_json() -> str:
    import json

    return json.dumps(json.loads(layout().to_json()), indent=2) + "\n"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="compare, do not write")
    args = parser.parse_args()
    text = layout_json()
    if args.check:
        same = OUT.is_file() and OUT.read_text() == text
        print(f"{OUT}: {'up to date' if same else 'differs; run tools/make_foxglove_layout.py'}")
        return 0 if same else 1
    OUT.parent.mkdir(parents=True, exist_ok=True)
    OUT.write_text(text)
    print(f"wrote {OUT}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
