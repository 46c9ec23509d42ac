"""A payload set at run time, the loop's side (LoopPort on a sim-clock loop, no server): the
control plane's numbers swapped into the loop's model between two ticks, in place (the
native handles the compiled calls address stay, nothing rebuilt); the observers' estimates at
rest then go to ~0 with the payload the simulated arm really holds, and show the missing
load's weight with a wrong one; the feed-forward carries it; refused while the arm moves;
flight-log events with its values."""

from __future__ import annotations

import tracemalloc
from pathlib import Path

import numpy as np
import pytest

from hofto_hw.config.loader import load_config
from hofto_hw.config.models import SystemConfig
from hofto_hw.config.payload import PayloadConfig
from hofto_hw.control.joint_motion import HOLD, MOVE
from hofto_hw.control_plane import channel as ch
from hofto_hw.control_plane.port import LoopPort
from hofto_hw.model.payload import Payload, apply_payload, bare_link, link_numbers
from hofto_hw.runtime.compose import build, build_model
from safety.stop import EventKind

CONFIG = Path(__file__).resolve().parents[3] / "configs" / "er3a.yaml"
TRUE = PayloadConfig(mass=2.0, com=(0.01, -0.02, 0.06))  # what the simulated arm holds


def _config() -> SystemConfig:
    """er3a with no payload in the controller's model, 2 kg on the simulated arm (otherwise
    the model's links: the load is what is measured here), no collision monitor (an
    unmodelled load is measured here, not stopped)."""
    cfg: SystemConfig = load_config(CONFIG)
    safety = cfg.safety.model_copy(update={"payload": PayloadConfig(), "collision": None})
    run = cfg.run.model_copy(update={"simulated_payload": TRUE, "model_error": 0.0})
    return cfg.model_copy(update={"safety": safety, "run": run})


@pytest.fixture
def wired():
    cfg = _config()
    system = build(cfg, clock="sim", contact=False)
    chan = ch.Channel(system.tick.n, len(system.tick.observers), create=True)
    port = LoopPort(chan, system).attach()
    system.loop.run(max_ticks=1500)  # held at rest, the observers settled
    try:
        yield cfg, system, chan
    finally:
        port.detach()
        chan.close()
        system.close()


def _send(cfg: SystemConfig, chan: ch.Channel, seq: int, mass: float, com) -> None:
    """What the control plane sends: the numbers computed in its own model."""
    cp_model = build_model(cfg)
    p = Payload(mass, tuple(com))
    r = np.zeros((), ch.REQUEST_DTYPE)
    r["seq"], r["kind"] = seq, ch.REQ_PAYLOAD
    v = [mass, *com, *link_numbers(cp_model, bare_link(cp_model), p)]
    r["value"][: len(v)] = v
    assert chan.requests.push(r)


def _reply(system, chan: ch.Channel) -> tuple[int, str]:
    system.loop.run(max_ticks=2)
    (rep,) = chan.replies.drain()
    return int(rep["code"]), bytes(rep["text"]).decode()


def _weight(cfg: SystemConfig, q: np.ndarray, payload: PayloadConfig | None) -> np.ndarray:
    """The load's weight as the observers see it, minus (g(q) of the model with ``payload``
    minus without) [N·m]."""
    bare = build_model(cfg)
    with_load = build_model(cfg)
    if payload is not None:
        apply_payload(with_load, Payload(payload.mass, tuple(payload.com)))
    return bare.create_data().gravity(q) - with_load.create_data().gravity(q)


def _estimates_at_rest(system, ticks: int = 1500) -> np.ndarray:
    system.loop.run(max_ticks=ticks)
    tick = system.tick
    assert tick.motion.mode == HOLD and float(np.abs(tick.group.qd).max()) < 0.01
    return tick.tau_ext.copy()  # (observers, n)


def test_the_right_payload_takes_the_estimates_to_zero_a_wrong_one_shows_its_weight(
    wired,
) -> None:
    cfg, system, chan = wired
    tick, model = system.tick, system.model
    q = tick.group.q.copy()
    load = _weight(cfg, q, TRUE)
    assert np.abs(load).max() > 5.0  # 2 kg at the tool: several N·m on the shoulder
    before = _estimates_at_rest(system)
    for row in before:  # every observer sees the unmodelled load's weight
        np.testing.assert_allclose(row, load, atol=0.1 * np.abs(load).max())

    snap_handle = tick.snapshot._native.handle if tick.snapshot.native else None
    ff_handle = tick.feedforward._native.handle if tick.feedforward.native else None
    tau_ff = tick.tau_ff.copy()
    _send(cfg, chan, 1, TRUE.mass, TRUE.com)
    tracemalloc.start()
    system.loop.run(max_ticks=1)  # the tick whose poll swaps it in
    kept, _ = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    code, text = _reply(system, chan)
    assert (code, text) == (1, "payload active")
    assert kept < 4000, f"the swap kept {kept} B"
    assert model.payload == Payload(TRUE.mass, tuple(TRUE.com))
    if snap_handle is not None:  # swapped in place: the compiled calls' handles stay
        assert tick.snapshot._native.handle == snap_handle
        assert tick.snapshot._native.revision == model.revision
    if ff_handle is not None:
        assert tick.feedforward._native.handle == ff_handle
    system.loop.run(max_ticks=5)
    # the feed-forward holds the load's weight from the next ticks on
    np.testing.assert_allclose(tau_ff - tick.tau_ff, load, atol=0.02 * np.abs(load).max())

    right = _estimates_at_rest(system)
    assert np.abs(right).max() < 0.05 * np.abs(load).max(), right

    wrong = PayloadConfig(mass=0.5, com=TRUE.com)
    _send(cfg, chan, 2, wrong.mass, wrong.com)
    assert _reply(system, chan) == (1, "payload active")
    missing = load - _weight(cfg, q, wrong)  # 1.5 kg not in the model
    shown = _estimates_at_rest(system)
    for row in shown:
        np.testing.assert_allclose(row, missing, atol=0.1 * np.abs(load).max())

    ev = tick.stop.events
    got = [
        (int(ev.joint[i]), float(ev.value[i]))
        for i in range(ev.count)
        if ev.kind[i] == EventKind.PAYLOAD
    ]
    assert got == [(-1, 2.0), (0, 0.01), (1, -0.02), (2, 0.06)] + [
        (-1, 0.5), (0, 0.01), (1, -0.02), (2, 0.06)
    ]  # fmt: skip


def test_the_payload_is_refused_while_the_arm_moves(wired) -> None:
    cfg, system, chan = wired
    tick = system.tick
    tick.mode_request = MOVE  # the demo path
    system.loop.run(max_ticks=300)
    assert tick.motion.mode == MOVE and float(np.abs(tick.group.qd).max()) > 1e-3
    rev = system.model.revision
    _send(cfg, chan, 1, TRUE.mass, TRUE.com)
    code, text = _reply(system, chan)
    assert code == 0 and "moving" in text and "standstill" in text
    assert system.model.revision == rev and system.model.payload is None


def test_a_profile_switch_scales_the_drag_admittance_and_the_collision_thresholds() -> None:
    """The profile's content reaches the loop: M_a, B_a and every drag speed limit scaled
    in place from the drag section's, the collision thresholds too; back with 'normal'."""
    cfg: SystemConfig = load_config(CONFIG)
    system = build(cfg, clock="sim", contact=False)
    chan = ch.Channel(system.tick.n, len(system.tick.observers), create=True)
    port = LoopPort(chan, system).attach()
    try:
        system.loop.run(max_ticks=300)
        tick = system.tick
        adm = tick.drag.admittance
        sh = adm.shaping
        inv_mass, damping = adm.inv_mass.copy(), adm.damping.copy()
        v_max, vmax, v_tool = adm.v_max, sh.vmax.copy(), sh.v_tool
        arrays = (adm.inv_mass, adm.damping, sh.vmax)
        names = cfg.safety.profiles.names()
        task = cfg.safety.profiles.sets["contact-task"]
        r = np.zeros((), ch.REQUEST_DTYPE)
        r["seq"], r["kind"], r["arg"] = 1, ch.REQ_PROFILE, names.index("contact-task")
        r["value"][:4] = [task.collision_scale, *task.drag_factors()]
        assert chan.requests.push(r)
        assert _reply(system, chan) == (1, "profile active")
        np.testing.assert_allclose(adm.inv_mass, inv_mass / 2.0)
        np.testing.assert_allclose(adm.damping, damping * 2.0)
        np.testing.assert_allclose(sh.vmax, vmax * 0.4)
        assert adm.v_max == pytest.approx(v_max * 0.4) and sh.v_tool == pytest.approx(v_tool * 0.4)
        assert tick.collision.threshold_scale == 1.4
        assert all(
            a is b for a, b in zip(arrays, (adm.inv_mass, adm.damping, sh.vmax), strict=True)
        )
        r["seq"], r["arg"], r["value"][:4] = 2, names.index("normal"), [1.0, 1.0, 1.0, 1.0]
        assert chan.requests.push(r)
        assert _reply(system, chan) == (1, "profile active")
        np.testing.assert_array_equal(adm.inv_mass, inv_mass)
        np.testing.assert_array_equal(adm.damping, damping)
        assert adm.v_max == v_max and tick.collision.threshold_scale == 1.0
    finally:
        port.detach()
        chan.close()
        system.close()
