"""JointMotion.version: unchanged only while q, qd, qdd keep their bits (the tick reuses its
feed-forward on that promise), over random sequences of starts, moves, ramps, follows and
holds, on the numpy reference (no compiled kernels needed)."""

from __future__ import annotations

import numpy as np

from hofto_hw.control.joint_motion import DRAG, HOLD, DemoPath, JointMotion

N = 6


def _motion() -> JointMotion:
    path = DemoPath(np.linspace(0.1, 0.6, N), np.linspace(1.5, 4.0, N), ramp=0.3)
    return JointMotion(N, np.linspace(2.0, 7.0, N), path)


def _bits(m: JointMotion) -> bytes:
    return m.q.tobytes() + m.qd.tobytes() + m.qdd.tobytes()


def test_a_hold_keeps_the_version_after_its_first_update() -> None:
    m = _motion()
    m.start(np.full(N, 0.2))
    v = m.version
    for k in range(5):
        m.update(1e-3 * k, 1e-3)
    assert m.version == v and m.mode == HOLD
    m.move(0.0)
    m.update(0.01, 1e-3)
    assert m.version != v  # the path moved the reference


def test_equal_version_means_equal_bits_over_random_operations() -> None:
    rng = np.random.default_rng(7)
    m = _motion()
    m.start(rng.normal(0.0, 0.5, N))
    t, seen = 0.0, {}
    unchanged = 0
    for _ in range(4000):
        op = rng.integers(0, 10)
        if op == 0:
            m.start(rng.normal(0.0, 0.5, N))
        elif op == 1:
            m.move(t)
        elif op == 2:
            m.ramp_down()
        elif op == 3:
            # a drag reference (a zero velocity too: following it still counts as a write)
            m.mode = DRAG
            qd = rng.normal(0.0, 0.1, N) if rng.random() < 0.7 else np.zeros(N)
            m.follow(m.q + 1e-3, qd, np.zeros(N))
        else:
            if m.mode == DRAG and rng.random() < 0.5:
                m.ramp_down()
            if m.mode != DRAG:
                t += 1e-3
                m.update(t, 1e-3)
        v = m.version
        if v in seen:
            unchanged += 1
            assert seen[v] == _bits(m), v
        seen[v] = _bits(m)
    assert unchanged > 100  # holds happened, and kept their version
