"""How the project's kernels are compiled (numba), and the one switch that runs them as Python.

Every module of hot-path arithmetic (hofto_hw/*/kernels.py, safety/, drivers/cia402/kernels.py,
runtime/) compiles its functions with :func:`jit` (or :func:`jit_inline` for small helpers) and
lets its user choose a backend: ``numba`` (compiled), ``python`` (the same source run by the
interpreter, :func:`compiled_or_python`; nothing is compiled) or ``auto`` (compiled when
:func:`available`). One source serves both; the numpy formulations of the formulas live in
tests/ as references.

numba is a dependency of the package. Whether a missing compiled path may run at all is the
loop's decision (``loop.acceleration``, :mod:`hofto_hw.runtime.acceleration`, which reads
:func:`available` and :func:`unavailable_reason`): :func:`available` is False when
``HOFTO_HW_NO_NUMBA=1`` (benchmarks and tests of the interpreted path) or when a kernel failed
to compile (:func:`warm`); ``auto`` then runs the kernels' source as Python. numba's own switch,
``NUMBA_DISABLE_JIT=1``, runs every kernel as Python too (for debugging).

Kernels are compiled with ``cache=True``; their users compile and warm them when built
(:func:`ready`), so no compilation happens inside a loop. numba's cache checks only the file
that defines a function, never the files of the kernels it calls (a documented limitation:
numba's "Notes on Caching"); the compiled tick calls kernels of a dozen files, so after an
edit of one of them it would load machine code of the old source. The cache therefore lives in
a folder per state of the sources (:func:`cache_folder`): ``$NUMBA_CACHE_DIR/hofto-<stamp>``,
or ``$XDG_CACHE_HOME/hofto-hw/numba/hofto-<stamp>`` (``~/.cache``) when ``NUMBA_CACHE_DIR`` is
not set, the stamp a hash of every source file's path, size and modification time (what numba
compares per file). A changed source compiles into a new folder; old folders are not used
again and may be deleted at any time.
"""

from __future__ import annotations

import hashlib
import os
import types
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import Any, Literal

import numba as _numba
import numpy as np

Backend = Literal["python", "numba", "auto"]

_DISABLED = os.environ.get("HOFTO_HW_NO_NUMBA", "") not in ("", "0")
_FAILED: str = ""  # first compilation failure, if any

#: the packages whose kernels call one another (beside this one in the checkout or install)
PACKAGES = ("hofto_hw", "drivers", "safety")


def sources_stamp(roots: Iterable[Path]) -> str:
    """16 hex digits of a hash of the relative path, size and modification time [ns] of every
    ``.py`` file under ``roots`` (folders; ``__pycache__`` skipped, a missing root ignored)."""
    h = hashlib.blake2b(digest_size=8)
    for root in roots:
        for folder, dirs, files in os.walk(root):
            dirs[:] = sorted(d for d in dirs if d != "__pycache__")
            for name in sorted(files):
                if name.endswith(".py"):
                    path = os.path.join(folder, name)
                    st = os.stat(path)
                    rel = os.path.relpath(path, os.path.dirname(root))
                    h.update(f"{rel}\0{st.st_size}\0{st.st_mtime_ns}\0".encode())
    return h.hexdigest()


def cache_folder(environ: Mapping[str, str] = os.environ) -> Path:
    """The folder numba's cache uses for the sources as they are now (module docstring)."""
    base = environ.get("NUMBA_CACHE_DIR", "")
    if not base:
        xdg = environ.get("XDG_CACHE_HOME", "") or os.path.join(
            environ.get("HOME", "") or os.path.expanduser("~"), ".cache"
        )
        base = os.path.join(xdg, "hofto-hw", "numba")
    top = Path(__file__).resolve().parent.parent
    return Path(base) / ("hofto-" + sources_stamp(top / p for p in PACKAGES))


# before any kernel is decorated: numba's cache locator reads the folder when it is
_numba.config.CACHE_DIR = str(cache_folder())


#: one dtype object per structured dtype in this process (:func:`interned`)
_DTYPES: dict[np.dtype, np.dtype] = {}


def interned(dt: np.dtype) -> np.dtype:
    """This process's one dtype object equal to ``dt`` (the first one seen). numba's
    dispatcher finds the compiled code for a structured array in a dict keyed by its dtype
    object: the object it first saw is found at once, an equal new one only after numpy
    compares the two field by field, on every call (~4 µs for the tick's hot record,
    tools/bench_tick.py). The structured arrays the tick's compiled calls take are allocated
    with interned dtypes, so that a second tick built in one process calls as fast as the
    first: ``hofto-hw run`` on a real bus builds one on the simulated arm first (to compile),
    as do tests and benchmarks."""
    return _DTYPES.setdefault(dt, dt)


def jit(fn: Callable[..., Any], **options: Any) -> Callable[..., Any]:
    """``fn`` compiled as every kernel is: cached, nogil, numpy's error model (a float
    division by zero gives inf or NaN instead of raising)."""
    try:
        return _numba.njit(cache=True, nogil=True, error_model="numpy", **options)(fn)
    except RuntimeError:
        # no writable cache folder (a service user under ProtectSystem=strict, a read-only
        # install): compile at start-up every time instead (NUMBA_CACHE_DIR points elsewhere)
        return _numba.njit(cache=False, nogil=True, error_model="numpy", **options)(fn)


def jit_inline(fn: Callable[..., Any]) -> Callable[..., Any]:
    """:func:`jit` for small helpers inlined into their callers at numba's IR level: a call
    between compiled functions passes each array as a dozen values and counts references on
    it, which costs more than these helpers' arithmetic. Called from Python, it is a kernel
    like any other."""
    return jit(fn, inline="always")


def available() -> bool:
    """True when the compiled kernels can run (not disabled, none failed to compile)."""
    return not _DISABLED and not _FAILED


def unavailable_reason() -> str:
    """Why :func:`available` is False ('' when it is True)."""
    if _DISABLED:
        return "compiled kernels disabled by HOFTO_HW_NO_NUMBA"
    return _FAILED


def resolve(backend: Backend) -> Literal["python", "numba"]:
    """The backend a kernel user runs: ``auto`` is numba when :func:`available`, else
    python (the kernels' source run by the interpreter).

    ``numba`` when the compiled path is not available raises RuntimeError naming the reason.
    """
    if backend == "python":
        return "python"
    if backend not in ("numba", "auto"):
        raise ValueError(f"backend must be 'python', 'numba' or 'auto', got {backend!r}")
    if available():
        return "numba"
    if backend == "numba":
        raise RuntimeError(f"compiled kernels unavailable: {unavailable_reason()}")
    return "python"


def warm(call: Callable[[], object]) -> bool:
    """Run ``call`` (which invokes a kernel on scratch data) to compile it now; on a
    compilation failure, mark the compiled path unavailable and return False."""
    global _FAILED
    if not available():
        return False
    try:
        call()
    except Exception as exc:  # numba's TypingError/LoweringError, or a cache problem
        _FAILED = f"compiling the kernels failed ({type(exc).__name__}: {exc})"
        _FAILED = _FAILED.splitlines()[0]
        return False
    return True


def ready(backend: Backend, warm_call: Callable[[], object]) -> Literal["python", "numba"]:
    """The backend a kernel user runs: :func:`resolve`, and for numba :func:`warm` with
    ``warm_call`` now (compiled before the loop); python when that compilation fails."""
    chosen = resolve(backend)
    if chosen == "numba" and not warm(warm_call):
        return "python"
    return chosen


def compiled_or_python(fn: Callable[..., Any], backend: str) -> Callable[..., Any]:
    """The compiled kernel ``fn`` for the ``numba`` backend, else the same source as Python,
    the kernels it calls included (numba's ``py_func``; nothing is compiled): one source
    for both."""
    if backend == "numba":
        return fn
    py = getattr(fn, "py_func", fn)
    return _python_namespace(py.__globals__).get(py.__name__, py) if _kernel(fn) else py


def _kernel(obj: object) -> bool:
    """``obj`` is a numba-compiled function (it carries its Python source as ``py_func``)."""
    return isinstance(getattr(obj, "py_func", None), types.FunctionType)


#: id(a kernel module's globals) -> that namespace with every kernel in it as Python
_PYTHON: dict[int, dict[str, Any]] = {}


def _python_namespace(module_globals: dict[str, Any]) -> dict[str, Any]:
    """A copy of a kernel module's namespace in which every compiled function, its own and
    those it imported, is its Python source bound to such a namespace: a kernel's
    ``py_func`` alone would still call the compiled kernels it uses."""
    ns = _PYTHON.get(id(module_globals))
    if ns is not None:
        return ns
    ns = _PYTHON[id(module_globals)] = dict(module_globals)
    imported = []
    for name, obj in module_globals.items():
        if not _kernel(obj):
            continue
        py = obj.py_func
        if py.__globals__ is module_globals:
            ns[name] = types.FunctionType(
                py.__code__, ns, py.__name__, py.__defaults__, py.__closure__
            )
        else:
            imported.append((name, py))
    for name, py in imported:  # after the module's own: an import cycle finds them there
        ns[name] = _python_namespace(py.__globals__).get(py.__name__, py)
    return ns
