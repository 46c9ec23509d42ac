"""hofto_hw.jit: the backend a kernel user runs, and the kernels' source run as Python (the
observers' kernels as the example: they call each other)."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import numba
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


# ------------------------------------------------------------------ the cache's folder

_PROBE_A = """from hofto_hw.jit import jit
from hofto_hw._probe_b import inner


@jit
def outer(x):
    return inner(x) + 1.0
"""
_PROBE_B = "from hofto_hw.jit import jit\n\n\n@jit\ndef inner(x):\n    return x * {}\n"


def _tree(tmp_path: Path) -> Path:
    """A copy of the three packages' sources (no caches, no native library)."""
    top = Path(jit.__file__).resolve().parent.parent
    dst = tmp_path / "src"
    for pkg in jit.PACKAGES:
        shutil.copytree(top / pkg, dst / pkg, ignore=shutil.ignore_patterns("__pycache__", "*.so"))
    return dst


def test_the_stamp_follows_every_source_file_and_nothing_else(tmp_path: Path) -> None:
    src = _tree(tmp_path)
    roots = [src / p for p in jit.PACKAGES]
    first = jit.sources_stamp(roots)
    assert first == jit.sources_stamp(roots) and len(first) == 16
    (src / "safety" / "notes.txt").write_text("not a source")
    (src / "safety" / "__pycache__").mkdir()
    (src / "safety" / "__pycache__" / "x.py").write_text("x = 1\n")
    assert jit.sources_stamp(roots) == first
    kernels_py = src / "safety" / "kernels.py"
    st = kernels_py.stat()
    os.utime(kernels_py, ns=(st.st_atime_ns, st.st_mtime_ns + 1_000_000))  # touched
    touched = jit.sources_stamp(roots)
    assert touched != first
    kernels_py.write_text(kernels_py.read_text() + "\n")  # edited
    assert jit.sources_stamp(roots) not in (first, touched)


def test_the_cache_folder_is_keyed_under_numba_cache_dir_or_the_user_cache(tmp_path):
    env = {"NUMBA_CACHE_DIR": str(tmp_path / "c"), "HOME": "/nonexistent"}
    folder = jit.cache_folder(env)
    assert folder.parent == tmp_path / "c" and folder.name.startswith("hofto-")
    folder = jit.cache_folder({"XDG_CACHE_HOME": str(tmp_path / "x")})
    assert folder.parent == tmp_path / "x" / "hofto-hw" / "numba"
    assert jit.cache_folder({"HOME": str(tmp_path)}).parent == tmp_path / ".cache/hofto-hw/numba"
    assert str(jit.cache_folder()) == numba.config.CACHE_DIR  # what this process uses


def test_a_kernel_edited_in_another_file_is_compiled_again(tmp_path: Path) -> None:
    """numba's own cache would load ``outer`` compiled with the old ``inner`` (it checks only
    the file that defines ``outer``): the folder per state of the sources does not."""
    src = _tree(tmp_path)
    (src / "hofto_hw" / "_probe_a.py").write_text(_PROBE_A)
    b = src / "hofto_hw" / "_probe_b.py"
    b.write_text(_PROBE_B.format("2.0"))
    env = dict(os.environ, PYTHONPATH=str(src), NUMBA_CACHE_DIR=str(tmp_path / "cache"))
    env.pop("NUMBA_DISABLE_JIT", None)
    code = "from hofto_hw._probe_a import outer; print(outer(3.0))"

    def run() -> str:
        res = subprocess.run(
            [sys.executable, "-c", code], env=env, cwd=tmp_path, capture_output=True,
            text=True, timeout=300,
        )  # fmt: skip
        assert res.returncode == 0, res.stderr[-2000:]
        return res.stdout.strip()

    assert run() == "7.0"
    assert list((tmp_path / "cache").rglob("*.nbi")), "nothing was cached"
    b.write_text(_PROBE_B.format("10.0"))  # outer's file untouched
    assert run() == "31.0"


def test_interned_gives_one_dtype_object_per_layout() -> None:
    """Equal structured dtypes built apart are one object after interning (what numba's
    dispatcher finds at once); another layout stays another object."""
    import numpy as np

    def layout(n: int) -> np.dtype:
        return np.dtype([("z", np.float64, (4, n)), ("flags", np.int64)], align=True)

    a, b = layout(6), layout(6)
    assert a == b and a is not b
    assert jit.interned(a) is jit.interned(b) is jit.interned(a)
    assert jit.interned(layout(7)) is not jit.interned(a)
