"""Whether the tick's compiled path can run (``loop.acceleration``).

The compiled path is the numba kernels (a dependency of the package) and the native dynamics
library shipped in the wheel (hofto_hw/model/native); the tick has no other (its Python
reference lives in tests/). Without either, ``hofto-hw run`` refuses to start in one line
naming why, whatever ``loop.acceleration`` says. ``preferred`` accepts numba's own switch
(NUMBA_DISABLE_JIT=1: the same source as Python, for tests and debugging); ``required`` (the
service's configs) refuses that too.
"""

from __future__ import annotations

from typing import Any

from hofto_hw.errors import ConfigError


def jit_disabled() -> bool:
    """True when numba's own switch (NUMBA_DISABLE_JIT=1) runs the compiled path's source as
    Python: the same kernels, the native dynamics through ctypes; for tests and debugging,
    ~30-50x slower than compiled."""
    from numba import config

    return bool(config.DISABLE_JIT)


def missing() -> str:
    """Why the compiled path cannot run in this process ('' when it can). Loads the native
    library (the first call of a process decides)."""
    from hofto_hw import jit
    from hofto_hw.model import native

    if not jit.available():
        return jit.unavailable_reason()
    if not native.ready():
        return native.unavailable_reason()
    return ""


def require(mode: str, source: str) -> None:
    """``loop.acceleration`` of the config file ``source``: ConfigError when the compiled
    path is missing, or when ``required`` and numba's JIT is switched off."""
    why = missing()
    if why:
        raise ConfigError(
            f"{source}: loop.acceleration: {mode}, but the compiled tick is unavailable: {why} "
            "(the tick has no other path)"
        )
    if jit_disabled() and mode == "required":
        raise ConfigError(
            f"{source}: loop.acceleration: required, but the compiled tick is unavailable: "
            "NUMBA_DISABLE_JIT is set (the kernels would run as Python)"
        )


def report(system: Any) -> dict[str, Any]:
    """What the built ``system``'s tick runs: ``compiled`` (numba kernels and native dynamics
    both in use), ``kernels`` (numba | python), ``native`` (the snapshot runs the native
    dynamics), ``fused`` (the tick's fused call, while the tick has one), ``why`` (what is
    missing, '' when compiled) and ``jit`` (False: NUMBA_DISABLE_JIT runs that same path's
    source as Python)."""
    tick = system.tick
    kernels = "numba" if getattr(tick, "backend", "python") == "numba" else "python"
    native = bool(getattr(tick.snapshot, "native", False))
    out: dict[str, Any] = {
        "compiled": kernels == "numba" and native,
        "kernels": kernels,
        "native": native,
    }
    if hasattr(tick, "_fz"):
        out["fused"] = tick._fz is not None
    out["why"] = "" if out["compiled"] else (missing() or "the tick did not take the compiled path")
    out["jit"] = not jit_disabled()
    return out


def describe(rep: dict[str, Any]) -> str:
    """One line for the summary and the log: ``compiled (numba kernels, native dynamics)`` or
    ``Python reference (why)``."""
    if rep["compiled"]:
        parts = f"numba kernels, native dynamics{', fused call' if rep.get('fused') else ''}"
        if not rep.get("jit", True):
            return f"the compiled path as Python (NUMBA_DISABLE_JIT; {parts})"
        return f"compiled ({parts})"
    return f"Python reference ({rep['why']})"
