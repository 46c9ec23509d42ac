"""ModelData: a caller-owned workspace for the dynamics of a RobotModel (pinocchio's Data).

:class:`~hofto_hw.model.robot.RobotModel` holds constant parameters only; every consumer (each
observer, the plant, a controller, a logger) creates its own workspace with
``data = model.create_data()`` and calls the dynamics on it, so two consumers in one tick never
overwrite each other's results.

Equation (1) of the paper, joint side, SI units:

    M(q)·qdd + C(q, qd)·qd + g(q) + f(qd) = tau + tau_ext

Every method writes into ``out=`` or returns a view of a buffer of this workspace that stays
valid until the *same method* of the *same workspace* is called again (each method has its own
buffers, friction included). None allocates arrays; :meth:`frame_jacobian`,
:meth:`frame_position` and :meth:`tool_pose` (off the tick) return new arrays.
The workspace reads the model's parameters at every call, so a change of parameters
(``set_inertial_parameters``, ``rotor_inertia``, ``friction``) is seen by existing workspaces.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from types import ModuleType
from typing import TYPE_CHECKING

import numpy as np
import pinocchio as pin

from hofto_hw.errors import ModelError

if TYPE_CHECKING:
    from hofto_hw.model.friction import FrictionParams
    from hofto_hw.model.native import NativeModel
    from hofto_hw.model.robot import RobotModel


class FollowsModel:
    """A workspace whose kernel rows ``_W`` hold its model's friction (packed from
    ``_fr_src``) and whose native copy ``_native`` (None: none) its model's numbers."""

    model: RobotModel
    _W: np.ndarray
    _fr_src: FrictionParams
    _pack: Callable[[FrictionParams, np.ndarray], None]  # kernels.pack_friction
    _native: NativeModel | None

    def follow_model(self) -> None:
        """Make the workspace its model's current one (rare): the friction repacked when
        ``model.friction`` was replaced, the native copy synced when the parameters moved
        (identified parameters, rotor inertia, a payload). Nothing changes otherwise."""
        fr, nm = self.model.friction, self._native
        if fr is not self._fr_src:
            self._fr_src = fr
            self._pack(fr, self._W)
        if nm is not None and nm.stale:
            nm.sync()


class ModelData(FollowsModel):
    """Workspace of one consumer: pinocchio Data and every buffer. Arrays float64, shape (n,)
    or (n, n); q [rad], qd [rad/s], qdd [rad/s²], torques [N·m].

    :meth:`inverse_dynamics` (the tick's feed-forward) is pinocchio's RNEA plus the friction
    and the sum of one kernel (:func:`hofto_hw.model.kernels.add_friction`; its held-friction
    memory ``friction_state`` is a row of the kernel's workspace): ``backend`` "numba"/"auto"
    runs the kernel compiled, "python" (default) runs its Python source; ``backend`` says
    which runs. With ``native`` (and the native library shipped in the wheel,
    :mod:`hofto_hw.model.native`) and the compiled kernel, the RNEA runs inside that
    compiled call too (:func:`~hofto_hw.model.kernels.inverse_dynamics_native`): one call in
    all; ``native`` says whether it does. Without (a robot the native library refuses,
    ``HOFTO_HW_NO_NATIVE``, backend python) the RNEA is pinocchio's Python call: the same
    algorithm. The numpy implementation (RNEA + eq. (12) as numpy calls) is the reference in
    tests/hofto_hw/model/reference.py. A pinocchio outside pyproject's bound is refused in
    one line (:func:`hofto_hw.model.snapshot.require_supported_pinocchio`)."""

    def __init__(
        self,
        model: RobotModel,
        backend: str = "python",
        native: bool = True,
        hot: Mapping[str, np.ndarray] | None = None,
    ) -> None:
        # imported here: hofto_hw.model.kernels imports this module's package (and numba
        # loads with the first model data, not with the package)
        from hofto_hw import jit
        from hofto_hw.model import kernels as mk
        from hofto_hw.model.snapshot import require_supported_pinocchio

        require_supported_pinocchio(model)
        self.model = model
        self.pin_data = model.pin_model.createData()
        n = model.n
        self.n = n
        self._M = np.zeros((n, n))
        self._C = np.zeros((n, n))
        self._Cqd = np.zeros(n)
        self._g = np.zeros(n)
        self._nle = np.zeros(n)
        self._f = np.zeros(n)
        self._f_fd = np.zeros(n)  # friction inside forward_dynamics
        #: FrictionParams.torque's workspace (friction_torque, forward_dynamics), packed for
        #: ``_fr_fd``
        self._fr_fd = model.friction
        self._fscratch = model.friction.workspace()
        # its kernel compiled (or loaded from numba's cache) now, not in the first step of
        # whatever steps this model: an emulator answering a bus would stall there for seconds
        model.friction.torque(np.zeros(n), np.zeros(n), self._fscratch.copy())
        W = self._W = mk.workspace(n) if hot is None else hot["W"]
        #: held-friction sign (memory), see model.friction: a row of the kernel's workspace
        self.friction_state = W[mk.STATE]
        self._fr_src = model.friction
        self._pack = mk.pack_friction
        mk.pack_friction(self._fr_src, W)
        self._tau_id = np.zeros(n)
        self._qdd = np.zeros(n)
        self._tau_total = np.zeros(n)
        self._J = np.zeros((6, n))
        self._native = None
        fast = False
        if jit.resolve(backend) == "numba":  # type: ignore[arg-type]
            z = np.zeros(n)
            fast = jit.warm(lambda: mk.add_friction(z, z, W.copy(), np.zeros(n)))
            if fast and native:
                self._use_native(mk, jit)
        #: "numba": :meth:`inverse_dynamics`'s kernel runs compiled; "python": its Python source
        self.backend = "numba" if fast else "python"
        self._add_friction = jit.compiled_or_python(mk.add_friction, self.backend)
        #: True: :meth:`inverse_dynamics` is one compiled call with pinocchio's C++ RNEA inside
        #: (hofto_hw.model.native)
        self.native = self._native is not None

    @staticmethod
    def hot_fields(n: int) -> dict[str, np.dtype]:
        """The kernels' workspace W as a field of a caller-owned record (``hot=``: the
        constructor takes it, zeroed, instead of allocating)."""
        from hofto_hw.model import kernels as mk

        return {"W": np.dtype((np.float64, (mk.ROWS, n)))}

    def _use_native(self, mk: ModuleType, jit: ModuleType) -> None:
        """RNEA and the friction as one compiled call with pinocchio's C++ RNEA inside
        (hofto_hw.model.native), when the native library is built here; else nothing."""
        from hofto_hw.model import native

        nm = native.model_for(self.model)
        if nm is None:
            return
        z, W, fn = np.zeros(self.n), self._W, mk.inverse_dynamics_native
        if jit.warm(lambda: fn(z, z, z, W.copy(), np.zeros(self.n), nm.handle)):
            self._native = nm
            self._id_native = fn

    # ------------------------------------------------------------------ dynamics

    def mass_matrix(self, q: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """M(q) [kg·m²], symmetric, shape (n, n), rotor inertia included."""
        M = self._M if out is None else out
        np.copyto(M, pin.crba(self.model.pin_model, self.pin_data, q))
        return M

    def coriolis_matrix(
        self, q: np.ndarray, qd: np.ndarray, out: np.ndarray | None = None
    ) -> np.ndarray:
        """C(q, qd) [N·m·s/rad], shape (n, n), with Mdot = C + Cᵀ."""
        C = self._C if out is None else out
        np.copyto(C, pin.computeCoriolisMatrix(self.model.pin_model, self.pin_data, q, qd))
        return C

    def gravity(self, q: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """g(q) [N·m], shape (n,)."""
        g = self._g if out is None else out
        np.copyto(g, pin.computeGeneralizedGravity(self.model.pin_model, self.pin_data, q))
        return g

    def nonlinear_effects(
        self, q: np.ndarray, qd: np.ndarray, out: np.ndarray | None = None
    ) -> np.ndarray:
        """C(q, qd)·qd + g(q) [N·m], shape (n,)."""
        h = self._nle if out is None else out
        np.copyto(h, pin.nonLinearEffects(self.model.pin_model, self.pin_data, q, qd))
        return h

    def coriolis(self, q: np.ndarray, qd: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """C(q, qd)·qd [N·m], shape (n,)."""
        pm, pd = self.model.pin_model, self.pin_data
        c = self._Cqd if out is None else out
        np.copyto(c, pin.nonLinearEffects(pm, pd, q, qd))
        np.subtract(c, pin.computeGeneralizedGravity(pm, pd, q), out=c)
        return c

    def friction_torque(self, qd: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """f(qd) [N·m], shape (n,), eq. (12)."""
        return self._friction().torque(
            qd, self._f if out is None else out, self._fscratch, self.friction_state
        )

    def _friction(self) -> FrictionParams:
        """The model's friction, its workspace ``_fscratch`` repacked when it was replaced."""
        fr = self.model.friction
        if fr is not self._fr_fd:
            self._fr_fd = fr
            self._pack(fr, self._fscratch)
        return fr

    def inverse_dynamics(
        self, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray, out: np.ndarray | None = None
    ) -> np.ndarray:
        """M·qdd + C·qd + g + f [N·m]: the motor torque that produces qdd with no contact."""
        m = self.model
        tau = self._tau_id if out is None else out
        self.follow_model()
        nm = self._native
        if nm is not None:
            self._id_native(q, qd, qdd, self._W, tau, nm.handle)
            return tau
        # pinocchio's return (a transient copy of data.tau) is the kernel's input
        self._add_friction(_rnea(m.pin_model, self.pin_data, q, qd, qdd), qd, self._W, tau)
        return tau

    def forward_dynamics(
        self,
        q: np.ndarray,
        qd: np.ndarray,
        tau: np.ndarray,
        tau_ext: np.ndarray | None = None,
        out: np.ndarray | None = None,
    ) -> np.ndarray:
        """qdd [rad/s²] = M⁻¹·(tau + tau_ext - C·qd - g - f), shape (n,) (ABA)."""
        m = self.model
        total = self._tau_total
        fr = self._friction()
        np.subtract(tau, fr.torque(qd, self._f_fd, self._fscratch, self.friction_state), out=total)
        if tau_ext is not None:
            np.add(total, tau_ext, out=total)
        qdd = self._qdd if out is None else out
        np.copyto(qdd, pin.aba(m.pin_model, self.pin_data, q, qd, total))
        return qdd

    def reset_friction_state(self, held_sign: np.ndarray | None = None) -> None:
        """Forget the held-friction memory (0 = no held direction) or set it to ``held_sign``
        (n,) of -1/0/+1 (e.g. the direction of the last motion before a restart)."""
        if held_sign is None:
            self.friction_state.fill(0.0)
        else:
            np.copyto(self.friction_state, held_sign)

    # ------------------------------------------------------------------ kinematics

    def tool_jacobian(self, q: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """Geometric Jacobian of the tool frame, shape (6, n), rows (v_x, v_y, v_z, w_x, w_y,
        w_z) in the world-aligned frame at the tool origin [m/rad, 1], written into this
        workspace's (6, n) buffer (or ``out``)."""
        m = self.model
        J = self._J if out is None else out
        np.copyto(
            J,
            pin.computeFrameJacobian(
                m.pin_model, self.pin_data, q, m.tool_frame_id, pin.LOCAL_WORLD_ALIGNED
            ),
        )
        return J

    def frame_jacobian(self, q: np.ndarray, frame: str) -> np.ndarray:
        """Like :meth:`tool_jacobian` for any URDF frame; shape (6, n). Allocates."""
        m = self.model
        if not m.pin_model.existFrame(frame):
            raise ModelError(f"{m.name}: frame {frame!r} is not in the URDF")
        return pin.computeFrameJacobian(
            m.pin_model,
            self.pin_data,
            q,
            m.pin_model.getFrameId(frame),
            pin.ReferenceFrame.LOCAL_WORLD_ALIGNED,
        )

    def frame_position(self, q: np.ndarray, frame: str | None = None) -> np.ndarray:
        """World position [m] of ``frame`` (default: the tool), shape (3,). Allocates."""
        m = self.model
        fid = m.tool_frame_id if frame is None else m.pin_model.getFrameId(frame)
        pin.forwardKinematics(m.pin_model, self.pin_data, q)
        return pin.updateFramePlacement(m.pin_model, self.pin_data, fid).translation.copy()

    def tool_pose(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Tool position [m], shape (3,), and rotation matrix, shape (3, 3). Allocates."""
        m = self.model
        pin.forwardKinematics(m.pin_model, self.pin_data, q)
        placement = pin.updateFramePlacement(m.pin_model, self.pin_data, m.tool_frame_id)
        return placement.translation.copy(), placement.rotation.copy()


_rnea = pin.rnea
