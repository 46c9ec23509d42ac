"""Kernels of the model's per-tick arithmetic (numba): friction eq. (12), the snapshot's
inputs and the inverse dynamics' friction, each one call between pinocchio calls (or around
the native library's, :mod:`hofto_hw.model.native`).

On six joints this arithmetic is a few dozen floating-point operations; as numpy calls on
six-element arrays the time goes to the ~0.5 µs each call costs (and to its cold caches
inside a loop), so each use is one compiled call. These kernels are the ONE implementation
of the snapshot's and the feed-forward's arithmetic (:class:`~hofto_hw.model.snapshot.
DynamicsSnapshot`, :class:`~hofto_hw.model.data.ModelData`): compiled for backend numba, their
Python source (``py_func``) for backend python; :func:`friction` is also
:meth:`hofto_hw.model.friction.FrictionParams.torque` (the simulated plant's forward dynamics,
the workspace's friction_torque, the drag's friction bound). The numpy reference (pinocchio's
Python API, eq. (12) as numpy calls) is tests/hofto_hw/model/reference.py;
tests/hofto_hw/model/test_kernels.py checks that every path agrees with it to 1e-12 over
thousands of random steps, held-friction memory and NaN included.

Arguments are few (a compiled call costs ~0.1 µs per argument, more with cold caches): the
friction parameters, the held-friction memory and the outputs travel in one workspace array
``W`` (:data:`ROWS`, n) made by :func:`workspace` and filled by :func:`pack_friction`.
Availability, compilation and warming are :mod:`hofto_hw.jit`'s (one switch,
``HOFTO_HW_NO_NUMBA``). Kernels write only into the arrays passed in; none allocates.
"""

from __future__ import annotations

import math

import numpy as np

from hofto_hw.jit import jit, jit_inline
from hofto_hw.model.friction import FrictionParams

# rows of the workspace W (ROWS, n): outputs, the held-friction memory, then the friction
# parameters per joint (a scalar parameter or flag is repeated on every joint)
F, TOTAL, CT, STATE = range(4)  # f [N·m], tau - f [N·m], Cᵀ·qd [N·m], held sign (-1/0/+1)
COULOMB, VISCOUS, BIAS, STRIBECK_GAP, STRIBECK_VELOCITY, QUADRATIC, HELD = range(4, 11)
SMOOTH, HELD_VELOCITY, HAS_STRIBECK, HAS_QUADRATIC, HAS_HELD, HELD_PASSIVE = range(11, 17)
FLAGS = 17  # what snapshot_terms computes: FRICTION_TERM | CORIOLIS_T_TERM (| native terms)
Q_IN, QD_IN, QDD_IN, RNEA_OUT = range(18, 22)  # contiguous copies for the native library
ROWS = 22

FRICTION_TERM = 1
CORIOLIS_T_TERM = 2
#: W[FLAGS] >> NATIVE_SHIFT: the terms snapshot_native asks the native library for
#: (hofto_hw.model.native MASS | GRAVITY | NLE | CORIOLIS_T | ACCEL)
NATIVE_SHIFT = 2

try:  # the native library's C functions, bound by name (hofto_hw/model/native/dynamics.cpp;
    # loaded by hofto_hw.model.native.ready() before any kernel below is compiled or run)
    from numba import config as _nc
    from numba import types as _nt

    _dyn_terms = _nt.ExternalFunction(
        "hofto_dyn1_terms",
        _nt.void(_nt.voidptr, _nt.int64, _nt.voidptr, _nt.voidptr, _nt.voidptr, _nt.voidptr),
    )
    _dyn_rnea = _nt.ExternalFunction(
        "hofto_dyn1_rnea",
        _nt.void(_nt.voidptr, _nt.voidptr, _nt.voidptr, _nt.voidptr, _nt.voidptr),
    )
    if _nc.DISABLE_JIT:  # the kernels run as Python: the same C functions through ctypes
        from hofto_hw.model.native import python_rnea as _dyn_rnea
        from hofto_hw.model.native import python_terms as _dyn_terms
except Exception:  # no numba: the native path is never chosen (hofto_hw.model.native.ready)
    _dyn_terms = _dyn_rnea = None


def workspace(n: int) -> np.ndarray:
    """A zeroed workspace W (ROWS, n) float64 for the kernels of this module."""
    return np.zeros((ROWS, n))


def pack_friction(fr: FrictionParams, W: np.ndarray) -> None:
    """Write ``fr`` into the parameter rows of W: Fc, Fv, B [N·m(·s/rad)], Fs - Fc [N·m],
    vs [rad/s] (1 without Stribeck), Fq [N·m·s²/rad²], Fh [N·m] (0 for an absent term), v_s
    [rad/s] (0 = hard sign), v_h [rad/s], then 1.0/0.0 flags: Stribeck, quadratic, held, held
    passive. A copy: FrictionParams are constant once built (new parameters are a new object;
    callers repack when ``model.friction`` is replaced)."""
    W[COULOMB] = fr.coulomb
    W[VISCOUS] = fr.viscous
    W[BIAS] = fr.bias
    stribeck = fr._stribeck_gap is not None
    W[STRIBECK_GAP] = fr._stribeck_gap if stribeck else 0.0
    W[STRIBECK_VELOCITY] = fr.stribeck_velocity if stribeck else 1.0
    W[QUADRATIC] = fr.quadratic if fr.quadratic is not None else 0.0
    W[HELD] = fr.held if fr.held is not None else 0.0
    W[SMOOTH] = fr.smooth_velocity
    W[HELD_VELOCITY] = fr.held_velocity
    W[HAS_STRIBECK] = float(stribeck)
    W[HAS_QUADRATIC] = float(fr.quadratic is not None)
    W[HAS_HELD] = float(fr.held is not None)
    W[HELD_PASSIVE] = float(fr.held_passive)


@jit
def _sign(x: float) -> float:
    """np.sign for one float: -1, 0, 1 (NaN stays NaN)."""
    if x > 0.0:
        return 1.0
    if x < 0.0:
        return -1.0
    return x * 0.0


@jit
def _step(x: float, at_zero: float) -> float:
    """np.heaviside(x, at_zero) for one float (NaN stays NaN)."""
    if x > 0.0:
        return 1.0
    if x < 0.0:
        return 0.0
    if x == 0.0:
        return at_zero
    return x


@jit_inline
def coulomb_sign(v: float, smooth: float) -> float:
    """s(v) of eq. (12), the feature of Coulomb friction [1]: tanh(v / v_s) for a smoothing
    velocity ``smooth`` v_s > 0 [rad/s], sign(v) for v_s = 0 (v [rad/s])."""
    return math.tanh(v / smooth) if smooth > 0.0 else _sign(v)


@jit_inline
def held_advance(v: float, h: float, band: float) -> float:
    """The held sign after velocity v [rad/s]: sign(v) where |v| > ``band`` v_h [rad/s], else
    the previous held sign ``h`` (-1/0/+1); idempotent for a repeated v."""
    return h + (_sign(v) - h) * _step(abs(v) - band, 0.0)


@jit_inline
def stribeck_feature(v: float, s: float, vs: float) -> float:
    """exp(-(v/vs)²)·s(v) [1], the feature of the Stribeck gap Fs - Fc (vs [rad/s])."""
    t = v / vs
    return math.exp(-(t * t)) * s


@jit_inline
def quadratic_feature(v: float) -> float:
    """v·|v| [rad²/s²], the feature of quadratic friction Fq."""
    return abs(v) * v


@jit_inline
def held_feature(v: float, h: float, band: float, passive: bool) -> float:
    """exp(-(v/v_h)²)·h [1], the feature of held friction Fh (band v_h [rad/s], held sign h);
    ``passive``: times [v·h >= 0] (the term only resists motion)."""
    t = v / band
    t = math.exp(-(t * t)) * h
    return t * _step(v * h, 1.0) if passive else t


N_FEATURES = 6  # what friction_features returns (hofto_hw.model.friction.FEATURES)


@jit_inline
def friction_features(v: float, h: float, j: int, W: np.ndarray) -> tuple:
    """The features of eq. (12) of joint j at velocity v [rad/s] with held sign h: the partial
    derivatives of f_j with respect to Fc, Fs - Fc, Fv, B, Fq, Fh, 0.0 for a term the model
    (W's flags) does not have: identification's regressor columns (:func:`feature_matrix`).
    Made of the same term functions as :func:`friction_joint`'s torque."""
    s = coulomb_sign(v, W[SMOOTH, j])
    stribeck = 0.0
    if W[HAS_STRIBECK, j] != 0.0:
        stribeck = stribeck_feature(v, s, W[STRIBECK_VELOCITY, j])
    quadratic = quadratic_feature(v) if W[HAS_QUADRATIC, j] != 0.0 else 0.0
    held = 0.0
    if W[HAS_HELD, j] != 0.0:
        held = held_feature(v, h, W[HELD_VELOCITY, j], W[HELD_PASSIVE, j] != 0.0)
    return s, stribeck, v, 1.0, quadratic, held


@jit
def friction_joint(v: float, j: int, W: np.ndarray) -> float:
    """f_j(v) [N·m] of eq. (12) with every optional term: each term's feature (the functions
    above, which :func:`friction_features` returns for identification) times its parameter,
    in the numpy reference's order of operations; advances the held sign ``W[STATE, j]`` when
    the model has held friction."""
    s = coulomb_sign(v, W[SMOOTH, j])
    out = s * W[COULOMB, j]
    if W[HAS_STRIBECK, j] != 0.0:
        out = out + stribeck_feature(v, s, W[STRIBECK_VELOCITY, j]) * W[STRIBECK_GAP, j]
    out = out + v * W[VISCOUS, j]
    out = out + W[BIAS, j]
    if W[HAS_QUADRATIC, j] != 0.0:
        out = out + quadratic_feature(v) * W[QUADRATIC, j]
    if W[HAS_HELD, j] != 0.0:
        band = W[HELD_VELOCITY, j]
        h = held_advance(v, W[STATE, j], band)
        W[STATE, j] = h
        out = out + held_feature(v, h, band, W[HELD_PASSIVE, j] != 0.0) * W[HELD, j]
    return out


@jit
def held_series(qd: np.ndarray, band: float, h: np.ndarray, out: np.ndarray) -> None:
    """out[k] = the held sign (n,) after sample k of a velocity sequence qd (N, n) [rad/s] in
    time order (:func:`held_advance` with band v_h [rad/s]), starting from and advancing the
    held sign ``h`` (n,) in place."""
    for k in range(qd.shape[0]):
        for j in range(qd.shape[1]):
            h[j] = held_advance(qd[k, j], h[j], band)
            out[k, j] = h[j]


@jit
def feature_matrix(qd: np.ndarray, held: np.ndarray, W: np.ndarray, out: np.ndarray) -> None:
    """out[k, j] = :func:`friction_features` (qd[k, j], held[k, j], j, W), (N, n,
    :data:`N_FEATURES`): the friction columns of identification's linear regressor over a
    recording, velocities qd (N, n) [rad/s] and held signs (N, n) (:func:`held_series`)."""
    for k in range(qd.shape[0]):
        for j in range(qd.shape[1]):
            f = friction_features(qd[k, j], held[k, j], j, W)
            for i in range(N_FEATURES):
                out[k, j, i] = f[i]


@jit
def friction(qd: np.ndarray, W: np.ndarray) -> None:
    """W[F] = f(qd) [N·m], (n,), as FrictionParams.torque(qd, out, state=W[STATE])."""
    for j in range(qd.shape[0]):
        W[F, j] = friction_joint(qd[j], j, W)


@jit
def sample_finite(q: np.ndarray, qd: np.ndarray, tau: np.ndarray) -> bool:
    """Whether q, qd and tau are all finite, by the finiteness of their sums (the numpy
    path's check: one NaN or inf anywhere makes a sum non-finite)."""
    acc = 0.0
    for j in range(q.shape[0]):
        acc += q[j]
    acc2 = 0.0
    for j in range(qd.shape[0]):
        acc2 += qd[j]
    acc3 = 0.0
    for j in range(tau.shape[0]):
        acc3 += tau[j]
    return math.isfinite(acc + acc2 + acc3)


@jit
def snapshot_terms(
    q: np.ndarray, qd: np.ndarray, tau: np.ndarray, C: np.ndarray, W: np.ndarray
) -> bool:
    """The snapshot's arithmetic around pinocchio: is the sample finite (the sum of q, qd and
    tau, as the numpy reference's check); if so, with ``W[FLAGS] & FRICTION_TERM`` the friction
    ``W[F]`` = f(qd) and ``W[TOTAL]`` = tau - f, with ``& CORIOLIS_T_TERM`` ``W[CT]`` = Cᵀ·qd
    (C (n, n) evaluated at this sample). Returns the finiteness; W is untouched (held-friction
    memory included) for a non-finite sample."""
    if not sample_finite(q, qd, tau):
        return False
    n = qd.shape[0]
    flags = int(W[FLAGS, 0])
    if flags & FRICTION_TERM:
        for j in range(n):
            f = friction_joint(qd[j], j, W)
            W[F, j] = f
            W[TOTAL, j] = tau[j] - f
    if flags & CORIOLIS_T_TERM:
        for i in range(n):
            acc = 0.0
            for k in range(n):
                acc += C[k, i] * qd[k]
            W[CT, i] = acc
    return True


@jit
def add_friction(base: np.ndarray, qd: np.ndarray, W: np.ndarray, out: np.ndarray) -> None:
    """W[F] = f(qd) and out = base + f [N·m], (n,): the inverse dynamics' friction added to
    the rigid-body torque ``base`` (RNEA)."""
    for j in range(qd.shape[0]):
        fj = friction_joint(qd[j], j, W)
        W[F, j] = fj
        out[j] = base[j] + fj


@jit
def snapshot_native(
    q: np.ndarray, qd: np.ndarray, tau: np.ndarray, W: np.ndarray, O: np.ndarray, h: int
) -> bool:
    """The whole snapshot in one call: :func:`snapshot_terms`'s finiteness check and friction
    (``W[F]``, ``W[TOTAL]`` = tau - f), then the native library (handle ``h``) for the terms
    ``W[FLAGS] >> NATIVE_SHIFT`` into O (n + 4, n): rows 0..n-1 M, n g, n+1 nle, n+2 the model
    acceleration M⁻¹·(tau - f - nle), n+3 Cᵀ·qd. Returns the finiteness; W and O are untouched for a
    non-finite sample."""
    if not sample_finite(q, qd, tau):
        return False
    n = qd.shape[0]
    flags = int(W[FLAGS, 0])
    for j in range(n):  # contiguous float64 copies: the caller's arrays may be views
        W[Q_IN, j] = q[j]
        W[QD_IN, j] = qd[j]
    if flags & FRICTION_TERM:
        for j in range(n):
            f = friction_joint(qd[j], j, W)
            W[F, j] = f
            W[TOTAL, j] = tau[j] - f
    _dyn_terms(
        h,
        flags >> NATIVE_SHIFT,
        W[Q_IN].ctypes.data,
        W[QD_IN].ctypes.data,
        W[TOTAL].ctypes.data,
        O.ctypes.data,
    )
    return True


@jit
def inverse_dynamics_native(
    q: np.ndarray, qd: np.ndarray, qdd: np.ndarray, W: np.ndarray, out: np.ndarray, h: int
) -> None:
    """out = RNEA(q, qd, qdd) + f(qd) [N·m], (n,), in one call: the native library's RNEA
    (handle ``h``) and :func:`add_friction` (``W[F]`` = f, held memory advanced)."""
    n = qd.shape[0]
    for j in range(n):
        W[Q_IN, j] = q[j]
        W[QD_IN, j] = qd[j]
        W[QDD_IN, j] = qdd[j]
    _dyn_rnea(
        h, W[Q_IN].ctypes.data, W[QD_IN].ctypes.data, W[QDD_IN].ctypes.data, W[RNEA_OUT].ctypes.data
    )
    for j in range(n):
        fj = friction_joint(qd[j], j, W)
        W[F, j] = fj
        out[j] = W[RNEA_OUT, j] + fj
