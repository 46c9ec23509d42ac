"""The native library's build cache (hofto_hw/model/native/build.py) with a stand-in compiler:
one build for parallel processes, a failure remembered, the key following the compiler, one
line when there is no compiler."""

from __future__ import annotations

import os
import stat
import subprocess
import sys
from pathlib import Path

import pytest

from hofto_hw.model.native import build

ROOT = Path(__file__).resolve().parents[3]


def _compiler(folder: Path, version: str = "fakecxx 1.0", fail: bool = False) -> Path:
    """A stand-in C++ compiler: answers --version, logs each build, writes the -o file after a
    second (or fails with one error line)."""
    path = folder / f"cxx-{abs(hash((version, fail)))}"
    path.write_text(
        "#!/bin/sh\n"
        f'if [ "$1" = "--version" ]; then echo "{version}"; exit 0; fi\n'
        f'echo build >> "{folder}/calls"\n'
        "sleep 1\n"
        + ('echo "dynamics.cpp:1: error: boom" >&2; exit 1\n' if fail else "")
        + 'while [ $# -gt 0 ]; do [ "$1" = "-o" ] && out="$2"; shift; done\n'
        'printf lib > "$out"\n'
    )
    path.chmod(path.stat().st_mode | stat.S_IXUSR)
    return path


def _calls(folder: Path) -> int:
    f = folder / "calls"
    return len(f.read_text().splitlines()) if f.exists() else 0


def test_parallel_processes_build_once(tmp_path: Path) -> None:
    cxx = _compiler(tmp_path)
    env = {
        **os.environ,
        "PYTHONPATH": str(ROOT),
        "CXX": str(cxx),
        "HOFTO_HW_NATIVE_CACHE": str(tmp_path / "cache"),
    }
    code = "from hofto_hw.model.native import build; print(build.library())"
    procs = [
        subprocess.Popen([sys.executable, "-c", code], env=env, stdout=subprocess.PIPE, text=True)
        for _ in range(3)
    ]
    paths = {p.communicate(timeout=120)[0].strip() for p in procs}
    assert all(p.returncode == 0 for p in procs)
    assert len(paths) == 1
    lib = Path(paths.pop())
    assert lib.read_text() == "lib" and lib.parent == tmp_path / "cache"
    assert _calls(tmp_path) == 1


def test_a_failed_build_is_remembered(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("CXX", str(_compiler(tmp_path, fail=True)))
    monkeypatch.setenv("HOFTO_HW_NATIVE_CACHE", str(tmp_path / "cache"))
    with pytest.raises(build.BuildError, match=r"compiling dynamics.cpp failed \(see .*failed\)"):
        build.library()
    failed = next((tmp_path / "cache").glob("*.failed"))
    assert "error: boom" in failed.read_text()
    assert not list((tmp_path / "cache").glob("*.so"))  # no half-written library
    with pytest.raises(build.BuildError, match="the build failed before"):
        build.library()
    assert _calls(tmp_path) == 1  # not compiled again


def test_another_compiler_builds_another_library(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("HOFTO_HW_NATIVE_CACHE", str(tmp_path / "cache"))
    monkeypatch.setenv("CXX", str(_compiler(tmp_path, "fakecxx 1.0")))
    a = build.library()
    assert build.library() == a
    monkeypatch.setenv("CXX", str(_compiler(tmp_path, "fakecxx 2.0")))
    b = build.library()
    assert a != b and a.exists() and b.exists()
    assert _calls(tmp_path) == 2
    with pytest.raises(build.BuildError, match="not built yet"):
        monkeypatch.setenv("CXX", str(_compiler(tmp_path, "fakecxx 3.0")))
        build.library(build=False)


def test_no_compiler_is_one_line(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("CXX", str(tmp_path / "no-such-compiler"))
    with pytest.raises(build.BuildError, match=r"no C\+\+ compiler"):
        build.library()


def test_a_damaged_cached_library_is_built_again(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A cached library cut short or overwritten is never loaded (a truncated shared library
    crashes the process that maps it): its hash differs from the build's record, so it is
    built again, with one line saying why."""
    monkeypatch.setenv("CXX", str(_compiler(tmp_path)))
    monkeypatch.setenv("HOFTO_HW_NATIVE_CACHE", str(tmp_path / "cache"))
    lib = build.library()
    assert _calls(tmp_path) == 1
    assert build.library() == lib and _calls(tmp_path) == 1  # intact: the cache answers
    lib.write_bytes(b"li")  # cut short
    said: list[str] = []
    assert build.library(say=said.append) == lib
    assert _calls(tmp_path) == 2 and lib.read_text() == "lib"
    assert any("does not match its build record" in line for line in said)
    next((tmp_path / "cache").glob("*.sha256")).unlink()  # a library without its record
    assert build.library() == lib and _calls(tmp_path) == 3
