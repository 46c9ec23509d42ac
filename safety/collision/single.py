"""``CollisionMonitor``: the one-row form of the monitor for recordings and thresholds files
(one observer's estimate, one collision level, one phase): ``update(tau_ext, qd, dt)``."""

from __future__ import annotations

import numpy as np

from hofto_hw.config.collision import CollisionConfig
from safety.collision.monitor import Backend, CollisionLevels
from safety.collision.params import from_thresholds


class CollisionMonitor:
    """Per-joint thresholds with debounce, hysteresis, velocity/acceleration/reversal/
    standstill terms on one estimate (a :class:`CollisionLevels` with one row).

    Public state after :meth:`update` (views, valid until the next update):
    ``detected`` (bool), ``joints`` (n,) bool tripped joints, ``threshold`` (n,) [N·m] the
    effective thresholds, ``ratio`` (n,) |tau_ext_hat| / threshold (0 where tau_ext_hat is
    not finite), ``nonfinite`` (n,) bool joints whose qd or tau_ext_hat was NaN/inf in this
    update, ``fault_nonfinite`` (bool) any of them; the features ``accel``, ``moving``,
    ``reversal``, ``still`` (n,).
    """

    def __init__(self, cfg: CollisionConfig, backend: Backend = "auto") -> None:
        n = len(cfg.base)
        self.cfg = cfg
        self.n = n
        self.levels = CollisionLevels.from_params(from_thresholds({"row": cfg}), backend=backend)
        lv = self.levels
        self.backend = lv.backend
        self.base = np.asarray(cfg.base, dtype=float)
        par = lv.params.par[0]
        self.kv, self.ka, self.kr, self.ks = par[2, 0], par[3, 0], par[4, 0], par[5, 0]
        self.v_rev = cfg.reversal_velocity
        self.joints = lv.joints[0, 0]
        self.threshold = lv.threshold[0, 0]
        self.ratio = lv.ratio[0]
        self.nonfinite = lv.nonfinite
        self.accel, self.moving = lv.accel, lv.moving
        self.reversal, self.still = lv.reversal, lv.still
        self._tau = np.zeros((1, n))
        self._hits = lv.state.hits
        self._tick = 0

    @property
    def detected(self) -> bool:
        return bool(self._hits[0])

    @property
    def fault_nonfinite(self) -> bool:
        return bool(self._hits[1])

    def reset(self, qd: np.ndarray | None = None) -> None:
        """Forget all state; ``qd`` (n,) [rad/s] seeds the acceleration estimate."""
        self.levels.reset(qd)
        self._tick = 0

    def features(self, qd: np.ndarray, dt: float) -> None:
        """Advance the threshold features (accel, moving, reversal, still) by one tick of dt
        [s]. Joints whose ``qd`` is not finite keep their previous state."""
        self.levels.features(qd, dt)

    def update(self, tau_ext: np.ndarray, qd: np.ndarray, dt: float) -> bool:
        """One tick: estimated external torque (n,) [N·m], velocity (n,) [rad/s], dt [s].

        Returns whether any joint is in collision (also in ``detected``; which joints in
        ``joints``).
        """
        self._tau[0] = tau_ext
        self._tick += 1
        return self.levels.step(self._tau, qd, None, dt, self._tick)
