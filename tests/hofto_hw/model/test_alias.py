"""Model buffers alias (defect 3 of issue 7): within one workspace, friction_torque's result
survives forward and inverse dynamics (first written against the old shared-buffer API)."""

from __future__ import annotations

import numpy as np


def test_friction_result_survives_forward_and_inverse_dynamics(er3a_model) -> None:
    model = er3a_model
    rng = np.random.default_rng(1)
    q, qd, tau = rng.uniform(-1, 1, 6), rng.uniform(-2, 2, 6), rng.uniform(-5, 5, 6)
    data = model.create_data()
    f = data.friction_torque(qd)
    expected = f.copy()
    # "valid until the same method is called again": other methods must not overwrite it
    data.forward_dynamics(q, -qd, tau)
    data.inverse_dynamics(q, 2 * qd, tau)
    assert np.array_equal(f, expected)
