"""The press of the enabling input is bumpless for a CSP drive: the drag's position reference
goes on from the hold it commanded, not from the measured position. After an enable the
drives' servo still carries a following error (~1 mrad at joints 2-3 of the ER3A over
EtherCAT); a reference that jumps to the measured q is a 1 mrad step in one 1 ms cycle,
which the drive's velocity feed-forward turns into 1 rad/s and its torque into the limit
(a torque_limit stop right after the press, seen over EtherCAT)."""

from __future__ import annotations

import numpy as np

from hofto_hw.config.loader import load_config
from hofto_hw.control.drag import DragController
from hofto_hw.experiments.drag_sim import ER3A
from hofto_hw.model.robot import RobotModel

DT = 1e-3


def test_the_press_keeps_the_commanded_hold() -> None:
    cfg = load_config(ER3A)
    model = RobotModel.from_config(cfg.robot)
    drag = DragController(cfg.drag, model, cfg.robot.gravity)
    hold = np.array(cfg.robot.home)
    sag = np.array([0.0, -1.0e-3, -0.8e-3, 0.0, -0.3e-3, 0.0])  # the servo's following error
    q = hold + sag
    qd = np.zeros(model.n)
    tau = np.zeros(model.n)
    drag.start(hold)
    for _ in range(200):  # in drag mode, input not pressed yet
        drag.update(q, qd, tau, DT, False, False)
    drag.update(q, qd, tau, DT, True, False)
    assert drag.active
    # no hand force yet: the reference stays where the hold was (before: it jumped to q)
    step = np.abs(drag.q_cmd - hold).max()
    assert step < 1e-6, step
    assert np.abs(drag.qd_cmd).max() < 1e-3
