"""Run identification's linear algebra on one BLAS thread.

Identification makes thousands of small QR/SVD calls (60x60 to 600x60). Multi-threaded
OpenBLAS spends longer waking threads than computing on matrices this small, and on a busy
machine it is 10-20x slower than one thread (measured: 10 ms vs 0.5 ms for a 600x58 SVD).
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import ParamSpec, TypeVar

from threadpoolctl import threadpool_limits

P = ParamSpec("P")
R = TypeVar("R")


def one_blas_thread(fn: Callable[P, R]) -> Callable[P, R]:
    """Decorator: call ``fn`` with BLAS limited to one thread (restored afterwards)."""

    @functools.wraps(fn)
    def wrapper(*args: P.args, **kwargs: P.kwargs) -> R:
        with threadpool_limits(limits=1, user_api="blas"):
            return fn(*args, **kwargs)

    return wrapper
