"""Which observer backend the commands use: the compiled kernels when they are available,
else the same kernels run as Python, said once per process on stderr."""

from __future__ import annotations

import sys

from hofto_hw import jit

_said = False


def observer_backend() -> jit.Backend:
    """``auto``; prints one line on stderr (once) when the compiled kernels are unavailable."""
    global _said
    if not jit.available() and not _said:
        _said = True
        print(
            "hofto-hw: the observers run their kernels as Python, not compiled "
            f"({jit.unavailable_reason()})",
            file=sys.stderr,
        )
    return "auto"
