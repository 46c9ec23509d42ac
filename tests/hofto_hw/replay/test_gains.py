"""The observer gains ``hofto-hw tune`` tries: pole placement and the stability filter."""

from __future__ import annotations

import numpy as np
import pytest

from hofto_hw.config.models import HoftoConfig
from hofto_hw.replay.defaults import default_observer
from hofto_hw.replay.gains import hofto_by_poles, pole_gains, variants


@pytest.mark.parametrize(("order", "pole"), [(2, 10.0), (2, 80.0), (3, 5.0)])
def test_pole_gains_put_every_pole_of_the_linearisation_at_minus_p(order, pole) -> None:
    """eq. (17) with powers 1 has the error characteristic polynomial s^k + L1·s^(k-1) + ...
    + Lk (k = order + 2): its roots must all be -pole."""
    gains = pole_gains(order, pole, 3)
    assert len(gains) == order + 2 and all(len(row) == 3 for row in gains)
    coeffs = [1.0] + [row[0] for row in gains]
    assert np.allclose(np.poly([-pole] * (order + 2)), coeffs)
    roots = np.roots(coeffs)
    assert np.allclose(roots.real, -pole, rtol=1e-2) and np.allclose(roots.imag, 0.0, atol=pole)


def test_hofto_by_poles_is_the_runtime_form() -> None:
    cfg = hofto_by_poles(40.0, 6, substeps=4)
    assert isinstance(cfg, HoftoConfig)
    assert cfg.form == "eq17" and cfg.sigma == -0.05 and cfg.substeps == 4
    assert cfg.gains[0] == [160.0] * 6 and cfg.gains[3] == [40.0**4] * 6


def test_variants_refuse_unstable_gains_at_the_rate(setup) -> None:
    said: list[str] = []
    n = setup.model.n
    hofto, grid = variants(
        "hofto", default_observer("hofto", n), setup.model, 100.0, [], [20.0, 300.0], 4, said.append
    )
    labels = [v.label for v in hofto]
    assert labels == ["replay default", "poles -20 rad/s, 4 substeps"]
    assert [g["stable"] for g in grid] == [True, True, False]
    assert any("poles -300" in m and "unstable at 100 Hz" in m for m in said)
    # the same poles are stable with enough substeps: the rate and the substeps decide
    hofto8, _ = variants(
        "hofto", default_observer("hofto", n), setup.model, 100.0, [], [150.0], 8, said.append
    )
    assert [v.label for v in hofto8] == ["replay default", "poles -150 rad/s, 8 substeps"]
    hofto4, _ = variants(
        "hofto", default_observer("hofto", n), setup.model, 100.0, [], [150.0], 4, said.append
    )
    assert [v.label for v in hofto4] == ["replay default"]
    momentum, grid = variants(
        "momentum", default_observer("momentum", n), setup.model, 100.0, [20.0, 250.0], [], 1
    )
    assert [v.config.gain for v in momentum] == [[20.0] * n]  # 250 >= 2·rate
    assert grid == [{"label": "gain 20", "stable": True}, {"label": "gain 250", "stable": False}]
