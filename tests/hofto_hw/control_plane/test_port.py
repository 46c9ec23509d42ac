"""The loop's side of the control channel (LoopPort) on a sim-clock loop, no server: it
allocates nothing per tick, takes the stop word first, plays a streamed plan and ramps down
when the next row is not there yet, and holds the enabling input only within the lease."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest
from support.alloc import tick_memory

from hofto_hw.config.loader import load_config
from hofto_hw.config.models import SystemConfig
from hofto_hw.control.joint_motion import HOLD, MOVE_TO, RAMP_DOWN
from hofto_hw.control_plane import channel as ch
from hofto_hw.control_plane.port import LoopPort
from hofto_hw.runtime import teach
from hofto_hw.runtime.compose import build
from safety.stop import Fault

CONFIG = Path(__file__).resolve().parents[3] / "configs" / "er3a.yaml"


@pytest.fixture
def wired():
    cfg: SystemConfig = load_config(CONFIG)
    enable = cfg.drag.enable_input.model_copy(update={"source": "socket"})
    cfg = cfg.model_copy(update={"drag": cfg.drag.model_copy(update={"enable_input": enable})})
    system = build(cfg, clock="sim", contact=False)
    chan = ch.Channel(system.tick.n, len(system.tick.observers), create=True)
    port = LoopPort(chan, system).attach()
    system.loop.run(max_ticks=300)
    try:
        yield system, chan, port
    finally:
        port.detach()
        chan.close()
        system.close()


def _request(chan: ch.Channel, seq: int, kind: int, mode: int = 0, arg: int = 0) -> None:
    r = np.zeros((), ch.REQUEST_DTYPE)
    r["seq"], r["kind"], r["mode"], r["arg"] = seq, kind, mode, arg
    assert chan.requests.push(r)


def test_polling_allocates_nothing_per_tick(wired) -> None:
    system, chan, _ = wired
    grown, peak = tick_memory(system)
    assert system.tick.stop.latched == 0
    assert grown < 4000 and peak < 16000
    rec, extra = chan.read_state()
    assert int(rec["tick"]) == system.tick.tick and int(extra[ch.X_LOOP_TICKS]) > 0


def test_the_stop_word_latches_a_stop_request_in_the_next_tick(wired) -> None:
    system, chan, _ = wired
    tick = system.tick
    _request(chan, 1, ch.REQ_MODE, mode=HOLD)  # queued behind: the stop still goes first
    chan.ctl[ch.STOP_SEQ] += 1
    system.loop.run(max_ticks=2)
    assert tick.stop.latched_names() == ["stop_request"]
    assert int(chan.ctl[ch.STOP_ACK]) == int(chan.ctl[ch.STOP_SEQ])


def test_a_streamed_plan_plays_and_ramps_down_when_rows_are_not_there_yet(wired) -> None:
    system, chan, _ = wired
    tick, model = system.tick, system.model
    q0 = tick.motion.q.copy()
    pb = teach.plan_move(
        q0 + 0.3, q0, model, teach.motion_limits(system.cfg, model), 1.0 / system.rate_hz
    )
    rows = pb.traj.q.shape[0]
    assert rows > 400
    given = 250  # the control plane "falls behind": only these rows are written
    chan.plan_q[:given] = pb.traj.q[:given]
    chan.plan_qd[:given] = pb.traj.qd[:given]
    chan.plan_qdd[:given] = pb.traj.qdd[:given]
    chan.plan_start[:] = pb.traj.q[0]
    chan.ctl[ch.PLAN_ROWS] = rows
    chan.ctl[ch.PLAN_HEAD] = given
    chan.ctl[ch.PLAN_ID] = 7
    _request(chan, 2, ch.REQ_PLAY, mode=MOVE_TO, arg=7)
    system.loop.run(max_ticks=5)
    assert tick.motion.mode == MOVE_TO
    rep = chan.replies.drain()
    assert len(rep) == 1 and rep[0]["code"] == 1 and bytes(rep[0]["text"]) == b"playing"
    seen = []
    for _ in range(600):  # the loop never waits for the missing rows
        system.loop.run(max_ticks=1)
        seen.append(tick.motion.mode)
    assert RAMP_DOWN in seen and seen[-1] == HOLD
    assert int(chan.ctl[ch.PLAN_TAIL]) == given
    assert float(np.abs(tick.motion.qd).max()) == 0.0
    # the ramp is at the robot's acceleration limits (JointMotion.ramp_down), steeper than
    # the plan's: on this arm it may trip the torque limit (a category 1 stop), never more
    assert not tick.stop.latched & ~(1 << Fault.TORQUE_LIMIT), tick.stop.latched_names()


def test_the_enabling_input_is_pressed_only_within_the_lease(wired) -> None:
    system, chan, _ = wired
    tick = system.tick
    chan.ctl[ch.LEASE_NS] = time.monotonic_ns() + int(60e9)
    system.loop.run(max_ticks=1)
    assert tick.enable_input.pressed
    chan.ctl[ch.LEASE_NS] = time.monotonic_ns() - 1  # lapsed
    system.loop.run(max_ticks=1)
    assert not tick.enable_input.pressed
