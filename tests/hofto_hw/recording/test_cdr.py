"""Fixed-layout CDR batches are byte-identical to mcap-ros2-support's encoder."""

from __future__ import annotations

import numpy as np
from mcap_ros2._dynamic import serialize_dynamic

from hofto_hw.recording import cdr
from hofto_hw.recording import schemas as s


def encoder(type_name: str, msgdef: str):
    return serialize_dynamic(type_name, msgdef)[type_name]


def stamp(ns: int) -> dict:
    return {"stamp": {"sec": ns // 10**9, "nanosec": ns % 10**9}, "frame_id": ""}


def test_joint_state_batch_matches_the_reference_encoder():
    names = ["j1", "joint_22", "shoulder_lift_joint"]  # odd lengths exercise the padding
    dtype, template = cdr.joint_state_layout(names, position=True, velocity=True, effort=True)
    rng = np.random.default_rng(1)
    q, qd, tau = rng.normal(size=(3, 4, 3))
    t = np.array([0.0, 0.001, 1.5, 12345.678901])
    batch = cdr.fill_batch(dtype, template, 4)
    ns = cdr.set_stamps(batch, t)
    batch["position"], batch["velocity"], batch["effort"] = q, qd, tau
    enc = encoder(s.JOINT_STATE_TYPE, s.JOINT_STATE_MSGDEF)
    raw = batch.tobytes()
    for i in range(4):
        ref = enc(
            {
                "header": stamp(int(ns[i])),
                "name": names,
                "position": q[i].tolist(),
                "velocity": qd[i].tolist(),
                "effort": tau[i].tolist(),
            }
        )
        assert raw[i * dtype.itemsize : (i + 1) * dtype.itemsize] == ref


def test_effort_only_joint_state_matches():
    dtype, template = cdr.joint_state_layout(
        ["a", "b"], position=False, velocity=False, effort=True
    )
    batch = cdr.fill_batch(dtype, template, 1)
    cdr.set_stamps(batch, np.array([2.0]))
    batch["effort"] = [[1.0, -2.0]]
    ref = encoder(s.JOINT_STATE_TYPE, s.JOINT_STATE_MSGDEF)(
        {
            "header": stamp(2 * 10**9),
            "name": ["a", "b"],
            "position": [],
            "velocity": [],
            "effort": [1.0, -2.0],
        }
    )
    assert batch.tobytes() == ref


def test_wrench_stamped_matches():
    dtype, template = cdr.wrench_stamped_layout("tool0")
    batch = cdr.fill_batch(dtype, template, 1)
    cdr.set_stamps(batch, np.array([0.25]))
    batch["force"], batch["torque"] = [[1.0, 2.0, 3.0]], [[4.0, 5.0, 6.0]]
    head = stamp(250_000_000)
    head["frame_id"] = "tool0"
    ref = encoder(s.WRENCH_STAMPED_TYPE, s.WRENCH_STAMPED_MSGDEF)(
        {
            "header": head,
            "wrench": {
                "force": {"x": 1.0, "y": 2.0, "z": 3.0},
                "torque": {"x": 4.0, "y": 5.0, "z": 6.0},
            },
        }
    )
    assert batch.tobytes() == ref


def test_tick_status_matches():
    dtype, template = cdr.tick_status_layout()
    batch = cdr.fill_batch(dtype, template, 1)
    cdr.set_stamps(batch, np.array([1.001]))
    batch["tick"], batch["mode"], batch["faults"] = 2**40 + 3, 2, 0x80000001
    batch["bus_status"], batch["wakeup_us"], batch["compute_us"] = -3, 12.5, 250.25
    ref = encoder(s.TICK_STATUS_TYPE, s.TICK_STATUS_MSGDEF)(
        {
            "header": stamp(1_001_000_000),
            "tick": 2**40 + 3,
            "mode": 2,
            "faults": 0x80000001,
            "bus_status": -3,
            "wakeup_us": 12.5,
            "compute_us": 250.25,
        }
    )
    assert batch.tobytes() == ref
