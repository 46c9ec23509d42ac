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


def test_the_stop_sockets_word_latches_a_stop_request_and_is_acknowledged(wired) -> None:
    system, chan, _ = wired
    tick = system.tick
    _request(chan, 1, ch.REQ_MODE, mode=HOLD)
    chan.ctl[ch.STOP_FAST_SEQ] = 1  # the stop server's word (stop_server.py), STOP_SEQ untouched
    system.loop.run(max_ticks=2)
    assert tick.stop.latched_names() == ["stop_request"]
    assert int(chan.ctl[ch.STOP_FAST_ACK]) == 1
    assert int(chan.ctl[ch.STOP_ACK]) == int(chan.ctl[ch.STOP_SEQ])  # the other one as it was


def _starve(system, chan, plan_accel: np.ndarray) -> tuple[list[int], np.ndarray]:
    """Play a fast move of which only the rows up to its fastest are written (the control
    plane "falls behind" there), with ``plan_accel`` as the plan's limits in the channel;
    returns the motion's mode per tick and the largest |qdd| [rad/s²] per joint seen."""
    tick, model = system.tick, system.model
    limits = teach.motion_limits(system.cfg, model)
    q0 = tick.motion.q.copy()
    target = q0 + np.array([0.8, -0.6, 0.6, 1.0, 1.0, 1.0])
    pb = teach.plan_move(target, q0, model, limits, 1.0 / system.rate_hz)
    rows = pb.traj.q.shape[0]
    given = int(np.argmax(np.abs(pb.traj.qd).sum(axis=1)))  # starved at full speed
    assert 100 < given < rows - 100
    chan.plan_q[:given] = pb.traj.q[:given]
    chan.plan_qd[:given] = pb.traj.qd[:given]
    chan.plan_qdd[:given] = pb.traj.qdd[:given]
    chan.plan_start[:] = pb.traj.q[0]
    chan.plan_accel[:] = plan_accel
    chan.ctl[ch.PLAN_ROWS] = rows
    chan.ctl[ch.PLAN_HEAD] = given
    chan.ctl[ch.PLAN_ID] = 7
    _request(chan, 2, ch.REQ_PLAY, mode=MOVE_TO, arg=7)
    system.loop.run(max_ticks=5)
    assert tick.motion.mode == MOVE_TO
    rep = chan.replies.drain()
    assert len(rep) == 1 and rep[0]["code"] == 1 and bytes(rep[0]["text"]) == b"playing"
    seen, peak = [], np.zeros(model.n)
    for _ in range(given + 2000):  # the loop never waits for the missing rows
        system.loop.run(max_ticks=1)
        seen.append(tick.motion.mode)
        if tick.motion.mode == RAMP_DOWN:
            np.maximum(peak, np.abs(tick.motion.qdd), out=peak)
        if tick.motion.mode == HOLD or tick.stop.latched:
            break
    assert int(chan.ctl[ch.PLAN_TAIL]) == given
    return seen, peak


def test_a_starved_plan_ramps_down_at_its_own_limits_and_trips_nothing(wired) -> None:
    system, chan, _ = wired
    tick = system.tick
    limits = teach.motion_limits(system.cfg, system.model)
    seen, peak = _starve(system, chan, limits.acceleration)
    assert RAMP_DOWN in seen and seen[-1] == HOLD
    assert float(np.abs(tick.motion.qd).max()) == 0.0
    assert tick.stop.latched == 0, tick.stop.latched_names()
    # at the plan's limits (half the robot's here), not the robot's; before, the reference
    # also stood still for the starved tick: at 2 rad/s that kick latched torque_limit
    # (joint 1 at its 120 N·m) and collision
    assert np.all(peak <= limits.acceleration * (1 + 1e-9)), (peak, limits.acceleration)
    assert np.any(peak > 0.5 * limits.acceleration)  # it did decelerate from speed
    assert np.all(limits.acceleration < system.model.limits.acceleration)


def test_the_enabling_input_is_pressed_only_within_the_lease(wired) -> None:
    system, chan, _ = wired
    tick = system.tick
    chan.ctl[ch.LEASE_NS] = time.monotonic_ns() + int(60e9)
    system.loop.run(max_ticks=1)
    assert tick.enable_input.pressed
    chan.ctl[ch.LEASE_NS] = time.monotonic_ns() - 1  # lapsed
    system.loop.run(max_ticks=1)
    assert not tick.enable_input.pressed
