"""Tests of the compiled kernels: they run when numba is there, skip with the reason when it
is not, and fail under CI (where the dev extra installs numba) instead of skipping."""

from __future__ import annotations

import os

import pytest


def require_compiled_kernels() -> None:
    """Call at module level of a test module that needs the compiled kernels."""
    from hofto_hw import jit

    if jit.available():
        return
    if os.environ.get("CI"):
        pytest.fail(f"CI: compiled kernels must run: {jit.unavailable_reason()}")
    pytest.skip(
        f"compiled kernels unavailable: {jit.unavailable_reason()}", allow_module_level=True
    )
