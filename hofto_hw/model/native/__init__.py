"""Native dynamics: pinocchio's algorithms for the robot's model, called from numba kernels.

``dynamics.cpp`` (built with the package by setup.py, shipped as ``_dynamics.so`` next to this
file) runs pinocchio's own algorithms behind plain C functions, which the kernels of
:mod:`hofto_hw.model.kernels` call by name, so that a snapshot or a feed-forward is one
Python->compiled call (docs/ARCHITECTURE.md, "Native dynamics": why, how, build). Its model is
a copy of the Python pinocchio model's own numbers (:class:`NativeModel`), which follows
``RobotModel.revision``; same numbers, same algorithms, same terms (test_native.py: 1e-12).

The library is loaded only when the pinocchio it was built against has the installed one's
major.minor and, in a source checkout, when ``dynamics.cpp`` beside it is its source. Without
it, on a mismatch, without numba or with ``HOFTO_HW_NO_NATIVE=1`` (or ``HOFTO_HW_NO_NUMBA=1``)
:func:`ready` is False, :func:`unavailable_reason` says why in one line (printed once per
process on stderr) and the pinocchio-Python path runs for the offline commands;
``hofto-hw run`` refuses to start (hofto_hw.runtime.acceleration).
"""

from __future__ import annotations

import ctypes
import hashlib
import os
import sys
import weakref
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from hofto_hw.model.robot import RobotModel

#: joint kinds of dynamics.cpp, by pinocchio's short name
KINDS = {
    "JointModelRX": 0,
    "JointModelRY": 1,
    "JointModelRZ": 2,
    "JointModelRevoluteUnaligned": 3,
}
#: terms of hofto_dyn1_terms (dynamics.cpp's Terms)
MASS, GRAVITY, NLE, CORIOLIS_T, ACCEL = 1, 2, 4, 8, 16

_LIB: ctypes.CDLL | None = None
_REASON = ""  # why the native path is unavailable ('' = not tried yet or fine)
_SAID = False


def say_once(line: str) -> None:
    """Print ``line`` on stderr unless this process said something about the native path."""
    global _SAID
    if not _SAID:
        _SAID = True
        print(f"hofto-hw: {line}", file=sys.stderr)


def ready() -> bool:
    """True when the native library is loaded (the first call of a process decides). When
    False, :func:`unavailable_reason` says why and it is printed once per process."""
    global _REASON
    if _LIB is not None:
        return True
    if not _REASON:
        _REASON = _load()
    if _LIB is None:
        say_once(f"native dynamics unavailable, the pinocchio Python path runs ({_REASON})")
    return _LIB is not None


def unavailable_reason() -> str:
    """Why :func:`ready` is False ('' when it is True or was not asked yet)."""
    return "" if _LIB is not None else _REASON


def library_path() -> Path | None:
    """The native library shipped next to this module, ``_dynamics.so`` (None when the
    package was installed without it). Not a Python extension module: one name for every
    Python version (setup.py)."""
    path = Path(__file__).resolve().parent / "_dynamics.so"
    return path if path.is_file() else None


def _built_from(lib: ctypes.CDLL) -> tuple[tuple[int, int, int], str]:
    """The pinocchio version (major, minor, patch) and the dynamics.cpp hash ``lib`` was built
    from (dynamics.cpp's hofto_dyn1_pinocchio_version / hofto_dyn1_source_sha256)."""
    version = (ctypes.c_int64 * 3)()
    lib.hofto_dyn1_pinocchio_version.restype = None
    lib.hofto_dyn1_pinocchio_version.argtypes = [ctypes.c_void_p]
    lib.hofto_dyn1_pinocchio_version(ctypes.addressof(version))
    lib.hofto_dyn1_source_sha256.restype = ctypes.c_char_p
    return (int(version[0]), int(version[1]), int(version[2])), (
        lib.hofto_dyn1_source_sha256().decode()
    )


def built_against() -> str:
    """The pinocchio version the loaded library was built against ('' when not loaded)."""
    if _LIB is None:
        return ""
    return ".".join(map(str, _built_from(_LIB)[0]))


def mismatch(built: tuple[int, int, int], sha: str, source: Path | None) -> str:
    """Why a library built from pinocchio ``built`` and a dynamics.cpp of hash ``sha`` must not
    be loaded here ('' when it may): another pinocchio major.minor installed, or (in a source
    checkout) a ``source`` file that is not the one it was built from."""
    import pinocchio

    have = tuple(int(x) for x in pinocchio.__version__.split(".")[:2])
    if have != built[:2]:
        b = ".".join(map(str, built))
        return (
            f"the native library was built against pinocchio {b} but pinocchio "
            f"{pinocchio.__version__} is installed (install pin=={built[0]}.{built[1]}.* or "
            "reinstall hofto-hw from source against this pinocchio)"
        )
    if source is not None and source.is_file():
        if hashlib.sha256(source.read_bytes()).hexdigest() != sha:
            return f"{source} changed since the library was built (pip install -e . again)"
    return ""


def _load() -> str:
    """Load the shipped library; '' on success, else the reason."""
    global _LIB
    if os.environ.get("HOFTO_HW_NO_NATIVE", "") not in ("", "0"):
        return "disabled by HOFTO_HW_NO_NATIVE"
    from hofto_hw import jit

    if not jit.available():
        return jit.unavailable_reason() or "numba unavailable"
    path = library_path()
    if path is None:
        return (
            "this install has no native library (hofto_hw/model/native/_dynamics.so; a source "
            "checkout: pip install -e . again)"
        )
    try:
        lib = ctypes.CDLL(str(path))
        built, sha = _built_from(lib)
    except (OSError, AttributeError) as exc:
        return f"loading {path} failed ({exc})"
    why = mismatch(built, sha, path.with_name("dynamics.cpp"))
    if why:
        return why
    try:
        import llvmlite.binding

        # numba's kernels bind the C functions by name (hofto_hw.model.kernels)
        llvmlite.binding.load_library_permanently(str(path))
    except RuntimeError as exc:
        return f"loading {path} failed ({exc})"
    p, i64 = ctypes.c_void_p, ctypes.c_int64
    lib.hofto_dyn1_create.restype = p
    lib.hofto_dyn1_create.argtypes = [i64, p, p, p, p, p, p, p]
    lib.hofto_dyn1_destroy.restype = None
    lib.hofto_dyn1_destroy.argtypes = [p]
    lib.hofto_dyn1_set_inertia.restype = i64
    lib.hofto_dyn1_set_inertia.argtypes = [p, i64, p]
    lib.hofto_dyn1_terms.restype = None
    lib.hofto_dyn1_terms.argtypes = [p, i64, p, p, p, p]
    lib.hofto_dyn1_rnea.restype = None
    lib.hofto_dyn1_rnea.argtypes = [p, p, p, p, p]
    _LIB = lib
    return ""


def python_terms(h: int, terms: int, q: int, qd: int, tau: int, out: int) -> None:
    """hofto_dyn1_terms through ctypes (arguments as the kernels pass them: the handle, the
    terms, addresses): what :mod:`hofto_hw.model.kernels` calls when NUMBA_DISABLE_JIT runs
    its kernels as Python (numba's binding by name works in compiled code only)."""
    assert _LIB is not None, "native.ready() first"
    _LIB.hofto_dyn1_terms(int(h), int(terms), q, qd, tau, out)


def python_rnea(h: int, q: int, qd: int, qdd: int, out: int) -> None:
    """hofto_dyn1_rnea through ctypes (see :func:`python_terms`)."""
    assert _LIB is not None, "native.ready() first"
    _LIB.hofto_dyn1_rnea(int(h), q, qd, qdd, out)


def model_numbers(model: RobotModel) -> dict[str, np.ndarray]:
    """The Python pinocchio model's numbers as dynamics.cpp's hofto_dyn1_create reads them
    (contiguous arrays); ValueError naming a joint dynamics.cpp does not know."""
    pm = model.pin_model
    n = model.n
    parent = np.zeros(n, dtype=np.int64)
    kind = np.zeros(n, dtype=np.int64)
    axis = np.zeros((n, 3))
    placement = np.zeros((n, 12))
    inertia = np.zeros((n, 10))
    for j in range(n):
        jm = pm.joints[j + 1]
        name = jm.shortname()
        if name not in KINDS:
            raise ValueError(f"{model.name}: joint {model.joint_names[j]} is a {name}")
        kind[j] = KINDS[name]
        if name.endswith("Unaligned"):
            axis[j] = jm.extract().axis
        parent[j] = pm.parents[j + 1]
        M = pm.jointPlacements[j + 1]
        placement[j, :9] = M.rotation.reshape(-1)
        placement[j, 9:] = M.translation
        Y = pm.inertias[j + 1]
        Ic = Y.inertia
        inertia[j, 0] = Y.mass
        inertia[j, 1:4] = Y.lever
        inertia[j, 4:] = (Ic[0, 0], Ic[1, 0], Ic[1, 1], Ic[2, 0], Ic[2, 1], Ic[2, 2])
    return {
        "parent": parent,
        "kind": kind,
        "axis": axis,
        "placement": placement,
        "inertia": inertia,
        "armature": np.array(pm.armature, dtype=float),
        "gravity": np.array(pm.gravity.linear, dtype=float),
    }


def model_for(model: RobotModel) -> NativeModel | None:
    """A :class:`NativeModel` of ``model`` when the library is ready here and knows every
    joint of ``model``; else None, with one line said once."""
    if not ready():
        return None
    try:
        return NativeModel(model)
    except ValueError as exc:  # a joint the native library does not know
        say_once(f"native dynamics not used: {exc}")
        return None


class NativeModel:
    """One C++ pinocchio Model + Data for ``model`` (its own workspace, like pinocchio's Data:
    one per consumer). ``handle`` is the address the kernels take; :meth:`sync` rebuilds it
    when ``model.revision`` moved. Requires :func:`ready`."""

    def __init__(self, model: RobotModel) -> None:
        assert _LIB is not None, "native.ready() first"
        self.model = model
        self.handle = 0
        self.revision = -1
        self._finalizer: weakref.finalize | None = None
        self.sync()
        _NATIVES.add(self)

    def sync(self) -> None:
        """Make the C++ model the Python model's current numbers (a new handle)."""
        lib = _LIB
        assert lib is not None
        v = model_numbers(self.model)
        ptr = lib.hofto_dyn1_create(
            self.model.n,
            *(v[k].ctypes.data for k in ("parent", "kind", "axis", "placement", "inertia")),
            v["armature"].ctypes.data,
            v["gravity"].ctypes.data,
        )
        if not ptr:
            raise ValueError(f"{self.model.name}: the native dynamics refused the model")
        if self._finalizer is not None:
            self._finalizer()  # the old handle
        self.handle = int(ptr)
        self._finalizer = weakref.finalize(self, lib.hofto_dyn1_destroy, ptr)
        self.revision = self.model.revision

    def __reduce__(self) -> tuple:
        # a copy (copy, deepcopy, pickle) gets its own C++ model, never the same address
        return (NativeModel, (self.model,))

    @property
    def stale(self) -> bool:
        """True when the model's parameters changed since the handle was made."""
        return self.model.revision != self.revision

    def set_inertia(self, joint: int, address: int) -> None:
        """Joint ``joint``'s (0-based) link inertia := the 10 numbers at ``address`` (the
        layout of :func:`model_numbers`), in place: same handle, nothing allocated."""
        assert _LIB is not None
        if _LIB.hofto_dyn1_set_inertia(self.handle, joint, address) != 0:
            raise ValueError(f"{self.model.name}: no joint {joint} in the native model")


#: every live NativeModel (set_link_inertia finds a model's copies here)
_NATIVES: weakref.WeakSet[NativeModel] = weakref.WeakSet()


def set_link_inertia(model: RobotModel, joint: int, values: np.ndarray) -> None:
    """After ``model``'s link ``joint`` (0-based) got the inertia ``values`` (10 numbers, the
    layout of :func:`model_numbers`) and its revision one more: every native copy that was in
    step before takes the same numbers in place and stays in step (no rebuild, no new handle:
    the tick's compiled calls keep their addresses). A copy already behind syncs as before."""
    address = values.ctypes.data
    for nm in _NATIVES:
        if nm.model is model and nm.revision == model.revision - 1:
            nm.set_inertia(joint, address)
            nm.revision = model.revision
