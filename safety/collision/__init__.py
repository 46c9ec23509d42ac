"""Collision detection on the estimated external torque (safety decides, it never reads the
bus): ONE monitor for the real-time loop, flight-log replay, recordings and calibration.

Per level l (``contact``: reported, clears itself; ``collision``: a stop the stop controller
latches), observer row r (e.g. hofto, momentum) and joint j, with the ratio
rho = |tau_ext_hat[r, j]| / thr:

    thr = base[l, phase, r, j] + kv·|qd_j| + ka·|a_j| + kr·r_j + ks·s_j   (gains per l, r, j)

- ``phase`` is ``acceleration`` while any joint's reference acceleration exceeds
  ``acceleration_phase`` (and ``phase_hold`` seconds after), else ``nominal`` (Franka's two
  threshold sets; recordings have no reference and stay nominal);
- ``a`` is the acceleration from differentiated velocity, first-order low-passed: model errors
  in inertia show up as a residual proportional to acceleration (acceleration steps);
- ``r`` is a velocity-reversal indicator in [0, 1]: exp(-(qd/v_rev)²) weighted by how recently
  the joint last moved faster than v_rev (decaying with ``moving_time``), held with a decay of
  ``reversal_time``. Friction changes sign at a reversal and no friction model follows that
  exactly, so the residual spikes there; a joint that stands still (r -> 0) keeps its
  sensitive resting threshold, so a push on a holding arm is still seen;
- ``s`` = exp(-(qd/v_s)²) is the standstill indicator (``standstill_margin`` ks,
  ``standstill_velocity`` v_s; off by default): a joint at rest keeps the friction of its last
  direction of motion, which a separate standstill term covers without raising the base, the
  threshold in motion; with ``standstill_time`` T > 0 it rises with time constant T after a
  stop and drops at once when the joint moves.

A row trips a level on a joint after rho > 1 for ``debounce_time`` and releases after
rho < ``release_ratio`` for ``release_time`` (hysteresis). The deciding rows give the
decision: ``any`` (a row trips), ``all`` (every deciding row trips) or ``mean`` (fusion: the
mean over the deciding rows of rho, per joint, is debounced and must exceed 1). Every row
keeps its own first-crossing tick of the collision level, so detection delays can be
compared side by side. Optional: a limit on the tool force |F| of F = (Jᵀ)⁺·tau_ext.

Non-finite inputs: a NaN or inf in ``qd`` or ``tau_ext`` is reported in the same update
(``nonfinite`` names the joints, ``fault_nonfinite`` is the fault; with a stop controller,
NON_FINITE is reported) and never enters the filters: a joint with a non-finite velocity keeps
its last finite acceleration, moving and reversal state and its threshold uses its last
finite velocity, so detection on it goes on with its torque; a row with a non-finite torque
on a joint keeps that joint's debounce/hysteresis state and cannot trip or release it in that
update (nor can the fused row when a deciding row is non-finite there), while the other
joints and rows are judged as usual. Once the inputs are finite again the monitor works as
before. The monitor only *reports*: latching a fault and the stop category it commands
belong to the stop controller (safety/stop.py).

Modules: :mod:`params` (config -> constant arrays: the loop's CollisionLevelsConfig, or
thresholds-file CollisionConfigs as one collision level, one phase), :mod:`state`,
:mod:`kernel` (the one implementation of a tick and of the threshold formula above,
``kernel.threshold``, which replay, calibration and tuning call too; compiled by numba or run
as its Python source; the numpy reference it is tested against is in tests/), :mod:`monitor`
(:class:`CollisionLevels`, backend ``numpy|numba|auto``),
:mod:`single` (:class:`CollisionMonitor`, one row), :mod:`tool_force`. Per tick nothing
allocates.
"""

from safety.collision.monitor import CollisionLevels
from safety.collision.params import MonitorParams, from_levels_config, from_thresholds
from safety.collision.single import CollisionMonitor
from safety.collision.state import COLLIDED, CONTACT, NONFINITE

__all__ = [
    "COLLIDED",
    "CONTACT",
    "NONFINITE",
    "CollisionLevels",
    "CollisionMonitor",
    "MonitorParams",
    "from_levels_config",
    "from_thresholds",
]
