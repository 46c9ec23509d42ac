"""A CANopen master run as its own process (two-process tests): enable, CSP move, CST torque.

``python -m support.canopen_remote CONFIG INTERFACE CHANNEL`` prints one JSON object:
states after enable, q target and measured q after the CSP move, commanded torque, exchange
status counts, the master's problems list.
"""

from __future__ import annotations

import json
import sys

import numpy as np


def main(argv: list[str]) -> int:
    from drivers.canopen.master import CANopenTransport
    from drivers.cia402.drive_group import DriveGroup
    from drivers.cia402.state_machine import Mode
    from hofto_hw.config.loader import load_config

    config, interface, channel = argv
    cfg = load_config(config)
    t = CANopenTransport(
        channel,
        cfg.bus.drives,
        1.0 / cfg.loop.rate_hz,
        list(cfg.robot.joints),
        can_interface=interface,
        tpdo_deadline=0.05,
        heartbeat_timeout=1.0,
        sdo_timeout=1.0,
        boot_timeout=10.0,
    )
    out: dict = {}
    statuses: list[int] = []
    with t:
        g = DriveGroup(t, DriveGroup.from_config(t, cfg.bus).scaling, transition_timeout=2.0)
        g.configure(cfg.bus.drives)
        g.set_mode(Mode.CSP)
        g.enable()
        out["states"] = g.states.tolist()
        q0 = g.q.copy()
        target = q0 + np.array([0.1, -0.05, 0.05, 0.1, -0.1, 0.2])
        for k in range(1, 301):
            g.command_position(q0 + (target - q0) * min(1.0, k / 60))
            t.wait_next_cycle()
            statuses.append(g.cycle())
        out["q_target"] = target.tolist()
        out["q"] = g.q.tolist()
        tau = g.tau.copy()  # what holds the arm now
        tau_cmd = tau + np.array([1.0, -1.0, 0.5, 0.2, -0.2, 0.1])
        g.command_torque(tau_cmd)
        g.set_mode(Mode.CST)
        for _ in range(5):
            t.wait_next_cycle()
            statuses.append(g.cycle())
        out["tau_cmd"] = tau_cmd.tolist()
        out["status_counts"] = {str(s): statuses.count(s) for s in set(statuses)}
        out["late_frames"] = t.late_frames
        out["problems"] = t.problems()
    print(json.dumps(out), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
