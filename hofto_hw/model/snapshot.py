"""DynamicsSnapshot: the model terms of one tick, computed once from (q, qd, tau).

Every estimator of a tick reads the same dynamics at the same sample, so the tick computes
them once, into a caller-owned workspace, and hands the snapshot to each observer
(``observer.update_snapshot(snap, dt)``). A snapshot computes only what its consumers
declared (:class:`Needs`, the union of their ``needs``):

- ``MASS``: M(q) [kg·m²], (n, n), symmetric, rotor inertia included (CRBA);
- ``GRAVITY``: g(q) [N·m], (n,);
- ``NLE``: C(q, qd)·qd + g(q) [N·m], (n,);
- ``CORIOLIS_T``: C(q, qd)ᵀ·qd [N·m], (n,) (the momentum observer's beta term);
- ``FRICTION``: f(qd) [N·m], (n,), eq. (12);
- ``ACCEL``: M⁻¹·(tau - C·qd - g - f) [rad/s²], (n,), the model acceleration without
  contact (ABA; on the native path a Cholesky solve with CRBA's M, ABA when M is not
  numerically positive definite; implies FRICTION).

No copies: on the native path (below) the arrays are rows of one buffer the compiled call
writes, made once at construction; on the pinocchio-Python path they are views of pinocchio's
Data storage (``data.M``, ``data.g``, ``data.nle``, ``data.ddq``) taken once at construction
and rows of the kernel's workspace (``f``, ``ct_qd``); pinocchio writes into that storage in
place, so the views show each tick's values. A pinocchio that does not keep those views
stable or fill both triangles of M (measured once per process, :func:`pinocchio_traits`) is
refused in one line (pyproject's ``pin`` bound excludes it). ``q``, ``qd`` and ``tau`` are
references to the caller's arrays (the sample the terms belong to), valid while the caller
keeps them unchanged.

A sample with a NaN or inf (or a non-finite dt, checked by the consumers) is not evaluated:
``finite`` is False and the terms keep the last finite sample's values.

One implementation of the arithmetic around pinocchio's algorithms: the finiteness check,
friction eq. (12) with its held memory, tau - f and Cᵀ·qd are the kernels of
:mod:`hofto_hw.model.kernels`. Two ways to reach pinocchio's algorithms:

- native (production: ``backend="numba"``, the native library shipped in the wheel,
  :mod:`hofto_hw.model.native`): :meth:`~DynamicsSnapshot.compute` is ONE compiled call
  (:func:`~hofto_hw.model.kernels.snapshot_native`: the checks and friction, then pinocchio's
  own C++ algorithms the needs ask for on a copy of the model: CRBA, gravity, nonlinear
  effects, the acceleration by pinocchio's Cholesky of CRBA's M, Cᵀ·qd as the kinetic
  energy's gradient by one recursion; see dynamics.cpp);
- pinocchio's Python API (ABA, CRBA, Coriolis matrix, gravity, nonlinear effects) and one
  call of :func:`~hofto_hw.model.kernels.snapshot_terms`: compiled with ``backend="numba"``,
  its Python source with ``backend="python"``. Kept, not a second formula (the same
  pinocchio algorithms and the same kernel): for a robot the native library refuses (a
  prismatic joint: RobotModel accepts it, dynamics.cpp knows revolute joints only),
  ``native=False`` / ``HOFTO_HW_NO_NATIVE=1`` (``loop.acceleration: preferred``), and the
  interpreter path (``backend="python"``: a Python-source kernel cannot call the native
  library, which numba binds by name).

The numpy implementation these replaced (pinocchio's Python API, eq. (12) as numpy calls,
numpy products) is the reference in tests/hofto_hw/model/reference.py; the agreement tests
(tests/hofto_hw/model/test_snapshot.py, test_native.py, test_kernels.py) compare every path
with it over random states, held friction and non-finite samples included.

Cost: inside a loop whose other work flushes the caches each call costs ~2.5-4 µs more than
back to back, whatever it computes, so the number of calls is what counts: one on the native
path, one per pinocchio algorithm plus one otherwise.
"""

from __future__ import annotations

import enum
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from types import ModuleType
from typing import TYPE_CHECKING

import numpy as np
import pinocchio as pin

from hofto_hw.model.data import FollowsModel

if TYPE_CHECKING:
    from hofto_hw.model.robot import RobotModel


class Needs(enum.IntFlag):
    """Model terms a consumer of the snapshot reads."""

    NONE = 0
    MASS = enum.auto()
    GRAVITY = enum.auto()
    NLE = enum.auto()
    CORIOLIS_T = enum.auto()
    FRICTION = enum.auto()
    ACCEL = enum.auto()


@dataclass(frozen=True)
class PinocchioTraits:
    """What the installed pinocchio guarantees (measured, not assumed)."""

    version: str
    stable_views: bool  # data.M / data.g / ... are views of storage that algorithms update
    full_mass_matrix: bool  # crba fills both triangles of data.M, exactly symmetric


_TRAITS: PinocchioTraits | None = None


def pinocchio_traits(model: RobotModel) -> PinocchioTraits:
    """Check once per process (on ``model``'s kinematic tree) how pinocchio returns results."""
    global _TRAITS
    if _TRAITS is None:
        pm = model.pin_model
        pd = pm.createData()
        rng = np.random.default_rng(7)
        q1 = pin.randomConfiguration(pm) if np.all(np.isfinite(pm.upperPositionLimit)) else None
        if q1 is None:
            q1 = rng.uniform(-1.0, 1.0, pm.nq)
        q2 = q1 + rng.uniform(0.1, 0.5, pm.nq)
        pin.crba(pm, pd, q1)
        view = pd.M
        stable = bool(np.shares_memory(view, pd.M))
        M1 = np.array(view)
        pin.crba(pm, pd, q2)
        M2 = pin.crba(pm, pm.createData(), q2)
        stable = stable and not np.array_equal(view, M1) and np.array_equal(view, M2)
        full = bool(np.array_equal(M2, M2.T) and np.array_equal(np.asarray(pd.M), M2))
        _TRAITS = PinocchioTraits(pin.__version__, stable, full)
    return _TRAITS


def require_supported_pinocchio(model: RobotModel) -> None:
    """ModelError in one line unless the installed pinocchio keeps its Data results as stable
    views and fills both triangles of M (:func:`pinocchio_traits`; every ``pin`` within
    pyproject's bound does: the workspaces and snapshots read pinocchio's storage in place)."""
    t = pinocchio_traits(model)
    if not (t.stable_views and t.full_mass_matrix):
        from hofto_hw.errors import ModelError

        what = "stable Data views" if not t.stable_views else "a full (symmetric) CRBA matrix"
        raise ModelError(
            f"pinocchio {t.version} does not give {what}; hofto-hw needs pin>=4.1,<5 "
            "(pip install 'pin>=4.1,<5')"
        )


class DynamicsSnapshot(FollowsModel):
    """The model terms of one sample for a set of consumers; see the module docstring.

    ``needs`` is the union of the consumers' :class:`Needs`. ``backend`` "numba"/"auto" runs
    compiled: with ``native`` (and the native library built here) one call in all
    (:mod:`hofto_hw.model.native`), else the pinocchio Python calls and one kernel.
    :meth:`compute` fills the terms; read ``M``, ``g``, ``nle``, ``ct_qd``, ``f``, ``accel``
    (arrays, see above), ``q``, ``qd``, ``tau`` (the sample) and ``finite``. Allocation: none
    by this class; each pinocchio Python call returns a transient copy that is dropped at
    once (the binding allocates it; the snapshot reads the Data storage instead).
    """

    def __init__(
        self,
        model: RobotModel,
        needs: Needs | int,
        backend: str = "python",
        native: bool = True,
        hot: Mapping[str, np.ndarray] | None = None,
    ) -> None:
        from hofto_hw import jit
        from hofto_hw.model import kernels as mk

        needs = Needs(needs)
        if needs & Needs.ACCEL:
            needs |= Needs.FRICTION
        self.needs = needs
        self.model = model
        self.n = n = model.n
        self.data = model.create_data()  # pinocchio Data (and the traits check)
        self.pin_model = model.pin_model
        pd = self.pin_data = self.data.pin_data
        self.traits = pinocchio_traits(model)
        self.M, self.g, self.nle, self.accel, self._C = pd.M, pd.g, pd.nle, pd.ddq, pd.C
        self._hot = hot  # the caller's record fields (hot_fields), else None: allocated here
        W = self._W = mk.workspace(n) if hot is None else hot["W"]
        self.f, self._total, self.ct_qd = W[mk.F], W[mk.TOTAL], W[mk.CT]
        # the workspace's held-friction memory lives in W (reset_memory still works)
        self.data.friction_state = W[mk.STATE]
        W[mk.FLAGS] = (mk.FRICTION_TERM if needs & Needs.FRICTION else 0) | (
            mk.CORIOLIS_T_TERM if needs & Needs.CORIOLIS_T else 0
        )
        self._fr_src = model.friction
        mk.pack_friction(model.friction, W)
        self._pack = mk.pack_friction
        zero = np.zeros(n)
        self.q: np.ndarray = zero
        self.qd: np.ndarray = zero
        self.tau: np.ndarray = zero
        self.finite = True
        self._mass = bool(needs & Needs.MASS)
        self._gravity = bool(needs & Needs.GRAVITY)
        self._nle = bool(needs & Needs.NLE)
        self._ct = bool(needs & Needs.CORIOLIS_T)
        self._accel = bool(needs & Needs.ACCEL)
        self._fast = False
        self._native = None
        if jit.resolve(backend) == "numba":  # type: ignore[arg-type]
            if native:
                self._use_native(mk, jit)
            if self._native is None:
                self._fast = jit.warm(self._warm)
        #: "numba": compiled (one call with ``native``, else the pinocchio calls and one
        #: compiled call); "python": the pinocchio calls and the kernel's Python source
        self.backend = "numba" if self._fast else "python"
        self._terms = jit.compiled_or_python(mk.snapshot_terms, self.backend)
        #: True: :meth:`compute` is one compiled call with pinocchio's C++ algorithms inside
        self.native = self._native is not None

    @staticmethod
    def hot_fields(n: int) -> dict[str, np.dtype]:
        """The workspace W and the native call's output rows O (n+4, n) as fields of a
        caller-owned record (``hot=``: the constructor takes them, zeroed, instead of
        allocating)."""
        from hofto_hw.model import kernels as mk

        return {"W": np.dtype((np.float64, (mk.ROWS, n))), "O": np.dtype((np.float64, (n + 4, n)))}

    def _use_native(self, mk: ModuleType, jit: ModuleType) -> None:
        """The whole snapshot as one compiled call with pinocchio's C++ algorithms inside
        (hofto_hw.model.native), when the native library is built here; else nothing."""
        from hofto_hw.model import native

        n, needs = self.n, self.needs
        nm = native.model_for(self.model)
        if nm is None:
            return
        terms = (
            (native.MASS if needs & Needs.MASS else 0)
            | (native.GRAVITY if needs & Needs.GRAVITY else 0)
            | (native.NLE if needs & Needs.NLE else 0)
            | (native.CORIOLIS_T if needs & Needs.CORIOLIS_T else 0)
            | (native.ACCEL if needs & Needs.ACCEL else 0)
        )
        W = self._W
        W[mk.FLAGS] = int(W[mk.FLAGS, 0]) | (terms << mk.NATIVE_SHIFT)
        O = np.zeros((n + 4, n)) if self._hot is None else self._hot["O"]
        z = np.zeros(n)
        snap = mk.snapshot_native
        if not jit.warm(lambda: snap(z, z, z, W.copy(), O.copy(), nm.handle)):
            W[mk.FLAGS] = int(W[mk.FLAGS, 0]) & ((1 << mk.NATIVE_SHIFT) - 1)
            return
        self._O = O
        self.M, self.g, self.nle, self.accel, self.ct_qd = O[:n], O[n], O[n + 1], O[n + 2], O[n + 3]
        self._native = nm
        self._snap = snap
        self._fast = True

    def _warm(self) -> None:
        from hofto_hw.model import kernels as mk

        z = np.zeros(self.n)
        W = self._W.copy()  # scratch: the held-friction memory stays untouched
        mk.snapshot_terms(z, z, z, self._C, W)

    def reset_memory(self) -> None:
        """Forget the held-friction memory of this snapshot's workspace (a new run)."""
        self.data.reset_friction_state()

    def compute(self, q: np.ndarray, qd: np.ndarray, tau: np.ndarray) -> bool:
        """Evaluate the needed terms at the sample q [rad], qd [rad/s], tau [N·m] (n,).

        Returns ``finite``: False (and nothing evaluated) when the sample holds a NaN or inf.
        """
        self.q, self.qd, self.tau = q, qd, tau
        self.follow_model()
        nm = self._native
        if nm is not None:
            self.finite = finite = self._snap(q, qd, tau, self._W, self._O, nm.handle)
            return finite
        pm, pd = self.pin_model, self.pin_data
        # Coriolis first: its matrix is no term of the snapshot (only Cᵀ·qd is), so a
        # non-finite sample may pass through it; then one kernel call checks the sample and
        # does every bit of arithmetic (friction, tau - f, Cᵀ·qd); then the pinocchio
        # algorithms whose storage the snapshot's terms are, in any order (each one evaluates
        # its own kinematics from q)
        if self._ct:
            _coriolis(pm, pd, q, qd)
        self.finite = finite = self._terms(q, qd, tau, self._C, self._W)
        if not finite:
            return False
        if self._accel:
            _aba(pm, pd, q, qd, self._total)
        if self._mass:
            _crba(pm, pd, q)
        if self._gravity:
            _gravity(pm, pd, q)
        if self._nle:
            _nle(pm, pd, q, qd)
        return True

    def parts(self) -> dict[str, Callable[[np.ndarray, np.ndarray, np.ndarray], object]]:
        """The calls :meth:`compute` makes, by name, each callable alone as f(q, qd, tau) (for
        benchmarks; the compiled arithmetic advances the held-friction memory as compute
        does)."""
        pm, pd = self.pin_model, self.pin_data
        calls: dict[str, Callable[[np.ndarray, np.ndarray, np.ndarray], object]] = {}
        if self._native is not None:
            W, O, nm, snap = self._W, self._O, self._native, self._snap
            calls["native: finite, friction, pinocchio terms, Cᵀ·qd"] = lambda q, qd, tau: snap(
                q, qd, tau, W, O, nm.handle
            )
            return calls
        if self._ct:
            calls["coriolis matrix"] = lambda q, qd, tau: _coriolis(pm, pd, q, qd)
        W, C, terms = self._W, self._C, self._terms
        calls["kernel: finite, friction, Cᵀ·qd"] = lambda q, qd, tau: terms(q, qd, tau, C, W)
        if self._accel:
            calls["aba"] = lambda q, qd, tau: _aba(pm, pd, q, qd, tau)
        if self._mass:
            calls["crba"] = lambda q, qd, tau: _crba(pm, pd, q)
        if self._gravity:
            calls["gravity"] = lambda q, qd, tau: _gravity(pm, pd, q)
        if self._nle:
            calls["nle"] = lambda q, qd, tau: _nle(pm, pd, q, qd)
        return calls


# module globals: one dictionary lookup per call instead of a module attribute's two
_aba = pin.aba
_crba = pin.crba
_coriolis = pin.computeCoriolisMatrix
_gravity = pin.computeGeneralizedGravity
_nle = pin.nonLinearEffects
