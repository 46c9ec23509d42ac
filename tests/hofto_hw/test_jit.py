"""hofto_hw.jit: the backend a kernel user runs, and the kernels' source run as Python (the
observers' kernels as the example: they call each other)."""

from __future__ import annotations

import pytest
from support.compiled import require_compiled_kernels

from hofto_hw import jit
from hofto_hw.observers import kernels

require_compiled_kernels()


def test_backend_resolution():
    assert jit.resolve("python") == "python"
    assert jit.resolve("auto") == "numba"
    assert jit.resolve("numba") == "numba"
    with pytest.raises(ValueError, match="backend"):
        jit.resolve("fortran")  # type: ignore[arg-type]


def test_the_python_path_runs_every_kernel_it_calls_as_python():
    """``numpy``: the kernel's source with the kernels it calls as Python too (a kernel's
    py_func alone would call compiled helpers, compiling them under HOFTO_HW_NO_NUMBA)."""
    assert jit.compiled_or_python(kernels.hofto_update, "numba") is kernels.hofto_update
    for fn in (kernels.hofto_update, kernels.hofto_advance, kernels.bank_update):
        py = jit.compiled_or_python(fn, "python")
        assert not jit._kernel(py) and py.__code__ is fn.py_func.__code__
        assert not [name for name, v in py.__globals__.items() if jit._kernel(v)]
    assert (
        jit.compiled_or_python(kernels.hofto_step, "python")
        is (jit.compiled_or_python(kernels.hofto_update, "python").__globals__["hofto_step"])
    )
