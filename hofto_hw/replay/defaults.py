"""Observer settings for replaying recordings sampled at about 100 Hz (the public UR10e
recordings), used when neither the thresholds file nor the system config names the
observer. Gains are per joint and identical on all joints; SI units as in the config models.

- momentum: K_O = 20 1/s (a 50 ms first-order response);
- dob: low-pass 20 rad/s;
- direct: velocity differentiated and low-passed at 5 Hz;
- eso: triple pole at -15 rad/s (bandwidth parameterisation: 3·w0, 3·w0², w0³), stable
  under explicit Euler at dt = 0.01 s (w0·dt = 0.15);
- sta: NOT tuned for 100 Hz (its sign() stage chatters at dt = 0.01 s and these gains
  track a push too slowly); it has no calibrated thresholds;
- hofto: order 2, Levant's recursive form with lambda = 5, 3, 1.5, 1.1 (the paper's) and a
  Lipschitz constant L = 100 rad/s⁴ per joint: L1..L4 = lambda_i·L^(1/(4-i+1)). The paper's
  L = 300-400 chatters on 100 Hz data.
"""

from __future__ import annotations

from hofto_hw.config.models import (
    DirectConfig,
    DobConfig,
    EsoConfig,
    HoftoConfig,
    MomentumConfig,
    ObserverConfig,
    StaConfig,
)

OBSERVER_NAMES = ("hofto", "momentum", "eso", "dob", "sta", "direct")


def levant_gains(lipschitz: float, n_joints: int, lambdas: tuple[float, ...]) -> list[list[float]]:
    """Rows L_i = lambda_i·L^(1/(k-i+1)) (i = 1..k, k = len(lambdas)) of the recursive form."""
    k = len(lambdas)
    return [[lam * lipschitz ** (1.0 / (k - i))] * n_joints for i, lam in enumerate(lambdas)]


def default_observer(name: str, n_joints: int) -> ObserverConfig:
    """The default config of observer ``name`` for ~100 Hz recordings of an n-joint arm."""
    w0 = 15.0
    if name == "momentum":
        return MomentumConfig(gain=[20.0] * n_joints)
    if name == "dob":
        return DobConfig(cutoff=[20.0] * n_joints)
    if name == "direct":
        return DirectConfig(accel_filter_hz=5.0)
    if name == "eso":
        return EsoConfig(
            k1=[3.0 * w0] * n_joints, k2=[3.0 * w0**2] * n_joints, k3=[w0**3] * n_joints
        )
    if name == "sta":
        return StaConfig(l1=[20.0] * n_joints, l2=[60.0] * n_joints, l3=[20.0] * n_joints)
    if name == "hofto":
        return HoftoConfig(
            order=2,
            form="recursive",
            powers=[0.75, 2.0 / 3.0, 0.5, 0.0],
            gains=levant_gains(100.0, n_joints, (5.0, 3.0, 1.5, 1.1)),
        )
    raise KeyError(name)
