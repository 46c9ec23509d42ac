"""The native dynamics (pinocchio's C++ algorithms called from one numba kernel) against the
numpy reference over pinocchio's Python API (tests/hofto_hw/model/reference.py): every
snapshot term and the feed-forward within 1e-12, parameter changes followed, non-finite
samples, joint kinds, the build cache and the fallback."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from hofto_hw.config import load_config
from hofto_hw.model import native
from hofto_hw.model.friction import FrictionParams
from hofto_hw.model.payload import Payload, apply_payload
from hofto_hw.model.robot import RobotModel
from hofto_hw.model.snapshot import DynamicsSnapshot, Needs
from tests.hofto_hw.model.reference import ReferenceData, ReferenceSnapshot

ROOT = Path(__file__).resolve().parents[3]
ALL = Needs.MASS | Needs.GRAVITY | Needs.NLE | Needs.CORIOLIS_T | Needs.ACCEL
TOL = 1e-12
#: the snapshot's needs of the main job (HOFTO + momentum), of HOFTO alone (its own snapshot),
#: of the DOB beside the momentum observer, the acceleration alone: each takes another route
#: through dynamics.cpp
NEEDS_SETS = {
    "main job": Needs.MASS | Needs.GRAVITY | Needs.CORIOLIS_T | Needs.ACCEL,
    "hofto": Needs.MASS | Needs.ACCEL,
    "dob + momentum": Needs.MASS | Needs.GRAVITY | Needs.CORIOLIS_T | Needs.NLE,
    "acceleration alone": Needs.ACCEL,
}


@pytest.fixture(scope="module", autouse=True)
def _native_built() -> None:
    if not native.ready():
        reason = native.unavailable_reason()
        if os.environ.get("CI"):  # CI installs it (pip install -e . builds it in place)
            pytest.fail(f"native dynamics unavailable in CI: {reason}")
        pytest.skip(f"native dynamics unavailable: {reason}")


def _model(name: str) -> RobotModel:
    return RobotModel.from_config(load_config(ROOT / "configs" / f"{name}.yaml").robot)


def _samples(model: RobotModel, count: int, seed: int) -> list[tuple[np.ndarray, ...]]:
    rng = np.random.default_rng(seed)
    n = model.n
    out = []
    for _ in range(count):
        q = rng.uniform(-3.0, 3.0, n)
        # slow and fast velocities: the held-friction band (5e-3 rad/s) and beyond
        qd = (
            rng.uniform(-2.0, 2.0, n)
            * (rng.uniform(0, 1, n) < 0.7)
            * 10.0 ** rng.integers(-4, 1, n)
        )
        tau = rng.uniform(-50.0, 50.0, n)
        out.append((q, qd, tau))
    return out


def _agree(a: DynamicsSnapshot, b: DynamicsSnapshot) -> None:
    for term in ("M", "g", "nle", "ct_qd", "accel", "f"):
        x, y = getattr(a, term), getattr(b, term)
        scale = max(1.0, float(np.max(np.abs(y))))
        assert np.max(np.abs(x - y)) <= TOL * scale, term


def _pair(model: RobotModel) -> tuple[DynamicsSnapshot, DynamicsSnapshot]:
    ref = ReferenceSnapshot(model, ALL | Needs.FRICTION)
    fast = DynamicsSnapshot(model, ALL | Needs.FRICTION, "numba")
    assert fast.native
    return ref, fast


@pytest.mark.parametrize("name", ["er3a", "ur10e"])
def test_snapshot_terms_equal_the_pinocchio_python_path(name: str) -> None:
    model = _model(name)
    ref, fast = _pair(model)
    for q, qd, tau in _samples(model, 400, 3):
        assert ref.compute(q, qd, tau) and fast.compute(q, qd, tau)
        _agree(fast, ref)
    # the held-friction memory advanced alike
    np.testing.assert_array_equal(fast.data.friction_state, ref.data.friction_state)


@pytest.mark.parametrize("name", ["er3a", "ur10e"])
def test_inverse_dynamics_equals_rnea_plus_friction(name: str) -> None:
    model = _model(name)
    ref, fast = ReferenceData(model), model.create_data("numba")
    assert fast.native
    rng = np.random.default_rng(5)
    for q, qd, _ in _samples(model, 400, 4):
        qdd = rng.uniform(-5.0, 5.0, model.n)
        a = fast.inverse_dynamics(q, qd, qdd)
        b = ref.inverse_dynamics(q, qd, qdd)
        assert np.max(np.abs(a - b)) <= TOL * max(1.0, float(np.max(np.abs(b))))
        # non-contiguous inputs (a column of a matrix) give the same numbers
        cols = np.stack([q, qd, qdd], axis=1)
        c = fast.inverse_dynamics(cols[:, 0], cols[:, 1], cols[:, 2], out=np.zeros(model.n))
        np.testing.assert_array_equal(c, a)


def test_parameter_changes_are_followed() -> None:
    """Payload, identified inertial parameters, rotor inertia and friction changed after the
    workspaces were made: the native copy follows each (RobotModel.revision)."""
    model = _model("er3a")
    ref, fast = _pair(model)
    ff_ref, ff = ReferenceData(model), model.create_data("numba")
    samples = _samples(model, 20, 9)
    qdd = np.linspace(-1.0, 1.0, model.n)

    def check() -> None:
        for q, qd, tau in samples:
            assert ref.compute(q, qd, tau) and fast.compute(q, qd, tau)
            _agree(fast, ref)
            b = ff_ref.inverse_dynamics(q, qd, qdd)
            a = ff.inverse_dynamics(q, qd, qdd)
            assert np.max(np.abs(a - b)) <= TOL * max(1.0, float(np.max(np.abs(b))))

    check()
    before = np.array(fast.M)
    apply_payload(model, Payload(2.5, (0.01, -0.02, 0.06), (0.01, 0.0, 0.012, 0.0, 0.0, 0.008)))
    check()
    q0 = samples[-1][0]
    fast.compute(q0, np.zeros(model.n), np.zeros(model.n))
    assert not np.allclose(fast.M, before)  # the payload is in M now
    model.set_inertial_parameters(model.inertial_parameters() * 1.1)
    check()
    model.rotor_inertia = np.linspace(0.1, 0.6, model.n)
    check()
    model.friction = FrictionParams(
        np.full(model.n, 2.0), np.full(model.n, 0.5), np.zeros(model.n), held=np.ones(model.n)
    )
    check()


def test_follow_model_is_what_a_compute_does_on_a_change() -> None:
    """follow_model() (what the tick calls before its compiled call reads the workspaces):
    nothing to do leaves the native handle as it is; new parameters sync the native copy (a
    new handle at the model's revision); a new friction set is packed into the kernel rows."""
    from hofto_hw.model import kernels as mk

    model = _model("er3a")
    snap = DynamicsSnapshot(model, ALL | Needs.FRICTION, "numba")
    ff = model.create_data("numba")
    assert snap.native and ff.native
    for ws in (snap, ff):
        h = ws._native.handle
        ws.follow_model()
        assert ws._native.handle == h  # nothing moved: nothing rebuilt
    model.set_inertial_parameters(model.inertial_parameters() * 1.1)
    fr = FrictionParams(np.full(model.n, 2.0), np.full(model.n, 0.5), np.zeros(model.n))
    model.friction = fr
    for ws in (snap, ff):
        h = ws._native.handle
        assert ws._native.stale
        ws.follow_model()
        assert not ws._native.stale and ws._native.handle != h
        np.testing.assert_array_equal(ws._W[mk.COULOMB], fr.coulomb)
        np.testing.assert_array_equal(ws._W[mk.VISCOUS], fr.viscous)


@pytest.mark.parametrize("which", ["all", *NEEDS_SETS])
def test_non_finite_sample_keeps_the_last_terms(which: str) -> None:
    model = _model("ur10e")
    ref, fast = _pair(model) if which == "all" else _pair_of(model, NEEDS_SETS[which])
    q, qd, tau = _samples(model, 1, 2)[0]
    assert fast.compute(q, qd, tau) and ref.compute(q, qd, tau)
    kept = {t: np.array(getattr(fast, t)) for t in ("M", "g", "nle", "ct_qd", "accel", "f")}
    for bad in (np.nan, np.inf, -np.inf):
        for arr in (q, qd, tau):
            x = arr.copy()
            x[2] = bad
            args = [x if a is arr else a for a in (q, qd, tau)]
            assert not fast.compute(*args)
            assert not fast.finite
            for t, v in kept.items():
                np.testing.assert_array_equal(getattr(fast, t), v)
    assert fast.compute(q, qd, tau)
    _agree(fast, ref)


def _pair_of(model: RobotModel, needs: Needs) -> tuple[DynamicsSnapshot, DynamicsSnapshot]:
    ref = ReferenceSnapshot(model, needs | Needs.FRICTION)
    fast = DynamicsSnapshot(model, needs | Needs.FRICTION, "numba")
    assert fast.native
    return ref, fast


def _terms_of(snap: DynamicsSnapshot) -> list[str]:
    n = snap.needs
    pairs = [(Needs.MASS, "M"), (Needs.GRAVITY, "g"), (Needs.NLE, "nle")]
    pairs += [(Needs.CORIOLIS_T, "ct_qd"), (Needs.ACCEL, "accel"), (Needs.FRICTION, "f")]
    return [t for flag, t in pairs if n & flag]


@pytest.mark.parametrize("name", ["er3a", "ur10e"])
@pytest.mark.parametrize("which", list(NEEDS_SETS))
def test_each_route_of_the_terms_equals_the_pinocchio_python_path(name: str, which: str) -> None:
    """The acceleration by a Cholesky solve with CRBA's M and nonLinearEffects' nle: within
    1e-12 of pinocchio's ABA; every term within 1e-12 of pinocchio's Python path; the rows not
    asked for are never written."""
    model = _model(name)
    ref, fast = _pair_of(model, NEEDS_SETS[which])
    terms = _terms_of(fast)
    others = [t for t in ("M", "g", "nle", "ct_qd", "accel") if t not in terms]
    for q, qd, tau in _samples(model, 400, 8):
        assert ref.compute(q, qd, tau) and fast.compute(q, qd, tau)
        for t in terms:
            x, y = getattr(fast, t), getattr(ref, t)
            assert np.max(np.abs(x - y)) <= TOL * max(1.0, float(np.max(np.abs(y)))), t
        for t in others:
            assert not np.any(getattr(fast, t)), t


def test_the_acceleration_does_not_depend_on_what_else_is_computed() -> None:
    """The same acceleration, bit for bit, for every set of needs that has it: an observer's
    estimate must not change with the observers that share its snapshot (HOFTO's gains turn
    a last-bit difference into 1e-10 N·m)."""
    model = _model("er3a")
    sets = [needs for needs in NEEDS_SETS.values() if needs & Needs.ACCEL]
    assert len(sets) >= 3
    snaps = [DynamicsSnapshot(model, needs, "numba") for needs in sets]
    assert all(s.native for s in snaps)
    for q, qd, tau in _samples(model, 400, 9):
        for s in snaps:
            assert s.compute(q, qd, tau)
        for s in snaps[1:]:
            np.testing.assert_array_equal(s.accel, snaps[0].accel)


def _with_last_link(model: RobotModel, link: np.ndarray, rotor: float) -> RobotModel:
    pi = model.inertial_parameters()
    pi[-10:] = link
    model.set_inertial_parameters(pi)
    r = model.rotor_inertia
    r[-2:] = rotor
    model.rotor_inertia = r
    return model


def test_badly_conditioned_mass_matrix() -> None:
    """A wrist of 1e-7 its mass and no rotor inertia (cond M up to ~1e11): the acceleration by
    the Cholesky solve stays within 1e-12 of ABA's and solves M·a = tau - f - nle to
    rounding (backward error <= 1e-14)."""
    model = _model("er3a")
    _with_last_link(model, model.inertial_parameters()[-10:] * 1e-7, 0.0)
    ref, fast = _pair_of(model, NEEDS_SETS["main job"])
    worst = 0.0
    for q, qd, tau in _samples(model, 100, 12):
        assert ref.compute(q, qd, tau) and fast.compute(q, qd, tau)
        worst = max(worst, float(np.linalg.cond(ref.M)))
        a, b = fast.accel, ref.accel
        assert np.max(np.abs(a - b)) <= TOL * max(1.0, float(np.max(np.abs(b))))
        nle = pin.nonLinearEffects(model.pin_model, model.pin_model.createData(), q, qd)
        rhs = tau - fast.f - nle
        residual = np.linalg.norm(fast.M @ a - rhs)
        assert residual <= 1e-14 * (
            np.linalg.norm(fast.M, 2) * np.linalg.norm(a) + np.linalg.norm(rhs)
        )
    assert worst > 1e9  # the samples did reach a badly conditioned M


def test_singular_mass_matrix_gives_what_aba_gives() -> None:
    """A last link with its mass on the last axis and no rotational inertia nor rotor inertia:
    M is singular (its last row zero), the Cholesky pivot is zero, and ABA runs as before (its
    NaN, not another number)."""
    model = _model("er3a")
    link = np.zeros(10)
    link[0] = 1e-3
    _with_last_link(model, link, 0.0)
    ref, fast = _pair_of(model, NEEDS_SETS["main job"])
    for q, qd, tau in _samples(model, 20, 13):
        assert ref.compute(q, qd, tau) and fast.compute(q, qd, tau)
        assert not np.any(fast.M[-1])
        np.testing.assert_array_equal(fast.accel, ref.accel)
        for t in ("M", "g", "ct_qd", "f"):
            x, y = getattr(fast, t), getattr(ref, t)
            assert np.max(np.abs(x - y)) <= TOL * max(1.0, float(np.max(np.abs(y)))), t


def test_a_negative_link_mass_keeps_the_nonlinear_effects_of_rnea() -> None:
    """Identified parameters need not be physical: a link mass of -1 kg makes pinocchio's
    Coriolis matrix wrong (its composite inertias' summed masses cancel), so nle and the
    acceleration must not be built from it: both stay pinocchio's nonLinearEffects and ABA."""
    model = _model("er3a")
    link = model.inertial_parameters()[-10:]
    link[0] = -1.0
    _with_last_link(model, link, float(model.rotor_inertia[-1]))
    ref, fast = _pair(model)
    pm = model.pin_model
    pd = pm.createData()
    broken = 0
    for q, qd, tau in _samples(model, 50, 14):
        assert ref.compute(q, qd, tau) and fast.compute(q, qd, tau)
        C = pin.computeCoriolisMatrix(pm, pd, q, qd)
        off = C @ qd + pin.computeGeneralizedGravity(pm, pd, q) - ref.nle
        broken += bool(np.max(np.abs(off)) > 1e-6 * max(1.0, float(np.max(np.abs(ref.nle)))))
        for t in ("nle", "accel"):
            x, y = getattr(fast, t), getattr(ref, t)
            assert np.max(np.abs(x - y)) <= TOL * max(1.0, float(np.max(np.abs(y)))), t
    assert broken  # C·qd + g is not nle for these parameters


def _kinetic_energy_gradient(model: RobotModel, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
    """∂T/∂q by central differences of pinocchio's kinetic energy (a sum over the bodies, no
    composite inertia): the independent reference of Cᵀ·qd (Ṁ = C + Cᵀ, so Cᵀ·qd = ∂T/∂q)."""
    pm = model.pin_model
    pd = pm.createData()
    step = 1e-6
    grad = np.zeros(model.n)
    for k in range(model.n):
        e = np.zeros(model.n)
        e[k] = step
        up = pin.computeKineticEnergy(pm, pd, q + e, qd)
        down = pin.computeKineticEnergy(pm, pd, q - e, qd)
        grad[k] = (up - down) / (2.0 * step)
    return grad


@pytest.mark.parametrize("negative_mass", [False, True])
def test_coriolis_transpose_term_is_the_kinetic_energy_gradient(negative_mass: bool) -> None:
    """Cᵀ·qd by the momentum recursion (ct_qd_of, not the Coriolis matrix) equals ∂T/∂q by
    finite differences, for physical parameters and for a link mass of -1 kg (identified
    parameters need not be physical), where pinocchio's Coriolis matrix is off (its composite
    inertias' summed masses are clamped) and the recursion, which sums momenta, is not."""
    model = _model("er3a")
    if negative_mass:
        link = model.inertial_parameters()[-10:]
        link[0] = -1.0
        _with_last_link(model, link, float(model.rotor_inertia[-1]))
    fast = DynamicsSnapshot(model, NEEDS_SETS["main job"], "numba")
    alone = DynamicsSnapshot(model, Needs.CORIOLIS_T, "numba")  # its own forward kinematics
    assert fast.native and alone.native
    pm = model.pin_model
    pd = pm.createData()
    off_by_matrix = 0.0
    for q, qd, tau in _samples(model, 60, 15):
        assert fast.compute(q, qd, tau) and alone.compute(q, qd, tau)
        np.testing.assert_array_equal(alone.ct_qd, fast.ct_qd)
        grad = _kinetic_energy_gradient(model, q, qd)
        scale = max(1.0, float(np.max(np.abs(grad))))
        assert np.max(np.abs(fast.ct_qd - grad)) <= 1e-7 * scale
        by_matrix = pin.computeCoriolisMatrix(pm, pd, q, qd).T @ qd
        off_by_matrix = max(off_by_matrix, float(np.max(np.abs(by_matrix - grad))) / scale)
    if negative_mass:
        assert off_by_matrix > 1e-4  # the Coriolis matrix's route would be wrong here
    else:
        assert off_by_matrix <= 1e-7  # both routes are the gradient


def _chain(joints: list, seed: int = 11) -> RobotModel:
    """A serial chain of ``joints`` with random placements, inertias, armature, gravity."""
    pm = pin.Model()
    rng = np.random.default_rng(seed)
    parent = 0
    for i, jm in enumerate(joints):
        placement = pin.SE3(pin.exp3(rng.uniform(-1.0, 1.0, 3)), rng.uniform(-0.3, 0.3, 3))
        parent = pm.addJoint(parent, jm, placement, f"j{i + 1}")
        A = rng.uniform(-0.1, 0.1, (3, 3))
        rot = A @ A.T + 0.01 * np.eye(3)
        Y = pin.Inertia(rng.uniform(0.5, 3.0), rng.uniform(-0.1, 0.1, 3), rot)
        pm.appendBodyToJoint(parent, Y, pin.SE3.Identity())
    pm.addFrame(pin.Frame("tool", parent, 0, pin.SE3.Identity(), pin.FrameType.OP_FRAME))
    pm.armature = rng.uniform(0.0, 0.3, pm.nv)
    pm.gravity.linear = np.array([0.3, -0.2, -9.81])
    return RobotModel(pm, [f"j{i + 1}" for i in range(len(joints))], "tool", name="chain")


def test_every_joint_kind_agrees() -> None:
    """RX, RY, RZ and unaligned revolute joints (a URDF axis off x, y, z) with non-trivial
    placements."""
    model = _chain(
        [
            pin.JointModelRZ(),
            pin.JointModelRevoluteUnaligned(np.array([0.0, 0.6, 0.8])),
            pin.JointModelRY(),
            pin.JointModelRX(),
            pin.JointModelRevoluteUnaligned(np.array([0.48, -0.6, 0.64])),
            pin.JointModelRZ(),
            pin.JointModelRX(),
        ]
    )
    ref, fast = _pair(model)
    for q, qd, tau in _samples(model, 300, 6):
        assert ref.compute(q, qd, tau) and fast.compute(q, qd, tau)
        _agree(fast, ref)


def test_a_joint_kind_it_does_not_know_runs_the_python_path() -> None:
    """A prismatic joint is no joint of the native library: the snapshot and the feed-forward
    of such a model run pinocchio's Python path (same terms as the reference)."""
    model = _chain([pin.JointModelRZ(), pin.JointModelPZ(), pin.JointModelRY()])
    with pytest.raises(ValueError, match="j2 is a JointModelPZ"):
        native.model_numbers(model)
    ref = ReferenceSnapshot(model, ALL | Needs.FRICTION)
    fast = DynamicsSnapshot(model, ALL | Needs.FRICTION, "numba")
    assert not fast.native and fast.backend == "numba"
    ff, ff_ref = model.create_data("numba"), ReferenceData(model)
    assert not ff.native and ff.backend == "numba"
    for q, qd, tau in _samples(model, 50, 8):
        assert ref.compute(q, qd, tau) and fast.compute(q, qd, tau)
        _agree(fast, ref)
        b = ff_ref.inverse_dynamics(q, qd, tau)
        assert np.max(np.abs(ff.inverse_dynamics(q, qd, tau) - b)) <= TOL * max(
            1.0, float(np.max(np.abs(b)))
        )


def _run(code: str, **env: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        cwd=ROOT,
        env={**os.environ, "PYTHONPATH": str(ROOT), **env},
        timeout=300,
    )


def test_disabled_native_path_runs_python_pinocchio_and_says_so_once() -> None:
    code = (
        "from hofto_hw.config import load_config\n"
        "from hofto_hw.model.robot import RobotModel\n"
        "from hofto_hw.model.snapshot import DynamicsSnapshot, Needs\n"
        "m = RobotModel.from_config(load_config('configs/er3a.yaml').robot)\n"
        "a = DynamicsSnapshot(m, Needs.MASS | Needs.ACCEL, 'numba')\n"
        "b = DynamicsSnapshot(m, Needs.MASS, 'numba')\n"
        "d = m.create_data('numba')\n"
        "print(a.native, b.native, d.native, a.backend, d.backend)\n"
    )
    res = _run(code, HOFTO_HW_NO_NATIVE="1")
    assert res.returncode == 0, res.stderr
    assert res.stdout.split() == ["False", "False", "False", "numba", "numba"]
    lines = [ln for ln in res.stderr.splitlines() if "native" in ln]
    assert lines == [
        "hofto-hw: native dynamics unavailable, the pinocchio Python path runs "
        "(disabled by HOFTO_HW_NO_NATIVE)"
    ]


def test_a_copied_workspace_gets_its_own_native_model() -> None:
    """copy/deepcopy/pickle of a NativeModel make a new C++ model (never the same address, which
    the original frees when it goes)."""
    import copy
    import pickle

    model = _model("er3a")
    a = native.NativeModel(model)
    for b in (copy.copy(a), copy.deepcopy(a), pickle.loads(pickle.dumps(a))):
        assert b.handle and b.handle != a.handle
        assert b.revision == b.model.revision
    # the copy computes on its own C++ Data
    ff, twin = model.create_data("numba"), model.create_data("numba")
    twin._native = copy.deepcopy(ff._native)
    q, qd, _ = _samples(model, 1, 12)[0]
    np.testing.assert_array_equal(
        twin.inverse_dynamics(q, qd, qd, out=np.zeros(model.n)), ff.inverse_dynamics(q, qd, qd)
    )
