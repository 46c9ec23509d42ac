"""Build the native dynamics library (dynamics.cpp) once per machine, into a cache directory.

The library is compiled against the headers of the installed pinocchio (its cmeel prefix: the
pinocchio, Eigen and Boost headers of the ``pin``, ``cmeel-eigen`` and ``cmeel-boost`` wheels)
with the system C++ compiler. The file name carries a key of everything the machine code
depends on (the source, the pinocchio version, the compiler's version line, the flags and the
header prefix), so a new pinocchio or compiler builds a new library and an old one is never
loaded by mistake. Parallel processes take a file lock: one compiles, the others wait and load
its result. A failed build is remembered (``<key>.failed`` holds the compiler's last lines) so
that later processes fall back at once instead of compiling for a minute each again.

Cache directory: ``HOFTO_HW_NATIVE_CACHE``, else ``$XDG_CACHE_HOME/hofto-hw/native``, else
``~/.cache/hofto-hw/native``. ``python -m hofto_hw.model.native`` builds it up front (CI does).
"""

from __future__ import annotations

import fcntl
import hashlib
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

SOURCE = Path(__file__).with_name("dynamics.cpp")

#: pinocchio's own compile definitions (its CMake config exports them); -O3: the algorithms ran
#: ~15 % faster than at -O2 here (same numbers: no -ffast-math, no -march), same build time
FLAGS = (
    "-std=c++17",
    "-O3",
    "-fPIC",
    "-shared",
    "-DNDEBUG",
    "-DBOOST_MPL_LIMIT_LIST_SIZE=30",
    "-DBOOST_MPL_LIMIT_VECTOR_SIZE=30",
    "-DBOOST_MPL_CFG_NO_PREPROCESSED_HEADERS",
    "-DBOOST_FUSION_INVOKE_MAX_ARITY=12",
)
#: the longest a build may take before it counts as failed [s]
BUILD_TIMEOUT = 900.0


class BuildError(RuntimeError):
    """The library cannot be built here (no compiler, no headers, or the compiler failed)."""


def cache_dir() -> Path:
    """Where built libraries are kept (see the module docstring)."""
    env = os.environ.get("HOFTO_HW_NATIVE_CACHE")
    if env:
        return Path(env)
    xdg = os.environ.get("XDG_CACHE_HOME")
    base = Path(xdg) if xdg else Path.home() / ".cache"
    return base / "hofto-hw" / "native"


def header_prefix() -> Path:
    """The cmeel prefix holding pinocchio's, Eigen's and Boost's headers; BuildError if absent."""
    import pinocchio

    here = Path(pinocchio.__file__).resolve()
    for parent in here.parents:
        if parent.name == "cmeel.prefix":
            break
    else:
        raise BuildError(f"pinocchio at {here.parent} is not a cmeel install (no headers)")
    inc = parent / "include"
    for need, package in (
        ("pinocchio/multibody.hpp", "pin"),
        ("eigen3/Eigen/Core", "cmeel-eigen"),
        ("boost/variant.hpp", "cmeel-boost"),
    ):
        if not (inc / need).is_file():
            raise BuildError(f"no {inc / need} (the headers of the {package} package)")
    return parent


def compiler() -> tuple[str, str]:
    """The C++ compiler (``CXX`` or c++/g++/clang++ on PATH) and its version line."""
    names = [os.environ["CXX"]] if os.environ.get("CXX") else ["c++", "g++", "clang++"]
    for name in names:
        path = shutil.which(name)
        if path:
            try:
                out = subprocess.run(
                    [path, "--version"], capture_output=True, text=True, timeout=30, check=True
                ).stdout
            except (OSError, subprocess.SubprocessError) as exc:
                raise BuildError(f"{path} --version failed ({exc})") from None
            return path, (out.splitlines() or ["?"])[0]
    raise BuildError("no C++ compiler (install g++, or set CXX)")


def command(cxx: str, prefix: Path, output: Path) -> list[str]:
    """The compiler command line that builds ``output``."""
    inc = prefix / "include"
    return [
        cxx,
        *FLAGS,
        f"-I{inc}",
        f"-I{inc / 'eigen3'}",
        str(SOURCE),
        "-o",
        str(output),
    ]


def build_key(cxx_version: str, prefix: Path) -> str:
    """The cache key: a hash of what the machine code depends on."""
    import pinocchio

    h = hashlib.sha256()
    h.update(SOURCE.read_bytes())
    for part in (pinocchio.__version__, cxx_version, " ".join(FLAGS), str(prefix)):
        h.update(b"\0" + part.encode())
    return h.hexdigest()[:16]


def _intact(lib: Path, digest: Path) -> bool:
    """The library's bytes are the ones its build recorded (a cache file cut short or
    overwritten is built again instead of loaded)."""
    try:
        return hashlib.sha256(lib.read_bytes()).hexdigest() == digest.read_text().strip()
    except OSError:
        return False


def library(build: bool = True, say=None) -> Path:
    """The path of the built library, building it now if needed (and ``build``).

    ``say(line)`` is told once, before a build starts (~40 s of CPU). Raises BuildError
    with one line naming the reason when it cannot be had.
    """
    prefix = header_prefix()
    cxx, version = compiler()
    key = build_key(version, prefix)
    folder = cache_dir()
    lib = folder / f"libhofto_dyn-{key}.so"
    failed = folder / f"{key}.failed"
    digest = folder / f"{key}.sha256"  # the library's hash, written before the library
    if lib.is_file() and _intact(lib, digest):
        return lib
    if failed.is_file():
        raise BuildError(f"the build failed before (see {failed})")
    if not build:
        raise BuildError(f"not built yet ({lib})")
    try:
        folder.mkdir(parents=True, exist_ok=True)
        lock = open(folder / f"{key}.lock", "w")  # held until the build ends
    except OSError as exc:
        raise BuildError(f"cannot write the cache directory {folder} ({exc})") from None
    with lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # another process may be building it right now
        if lib.is_file():
            if _intact(lib, digest):
                return lib
            # loading a truncated or damaged shared library crashes the process (SIGBUS)
            if say is not None:
                say(f"the cached {lib.name} does not match its build record; building it again")
        if failed.is_file():
            raise BuildError(f"the build failed before (see {failed})")
        if say is not None:
            say(
                "building the native dynamics once for this machine (~40 s of CPU, minutes "
                f"on a loaded machine; cached in {folder})"
            )
        tmp = folder / f".{key}.{os.getpid()}.so"
        cmd = command(cxx, prefix, tmp)
        t0 = time.monotonic()
        try:
            res = subprocess.run(cmd, capture_output=True, text=True, timeout=BUILD_TIMEOUT)
        except subprocess.TimeoutExpired:
            res = None
        if res is None or res.returncode != 0:
            tmp.unlink(missing_ok=True)
            detail = "timed out" if res is None else "\n".join(res.stderr.splitlines()[-40:])
            failed.write_text(" ".join(cmd) + "\n" + detail + "\n")
            raise BuildError(f"compiling {SOURCE.name} failed (see {failed})")
        digest.write_text(hashlib.sha256(tmp.read_bytes()).hexdigest() + "\n")
        os.replace(tmp, lib)
        (folder / f"{key}.info").write_text(
            f"{' '.join(cmd)}\n{version}\nbuilt in {time.monotonic() - t0:.1f} s\n"
        )
    return lib


def main() -> int:
    """``python -m hofto_hw.model.native``: build (or find) the library, print its path."""
    t0 = time.monotonic()
    try:
        lib = library(say=lambda line: print(f"hofto-hw: {line}", file=sys.stderr))
    except BuildError as exc:
        print(f"hofto-hw: native dynamics unavailable: {exc}", file=sys.stderr)
        return 1
    print(f"{lib} ({time.monotonic() - t0:.1f} s)")
    return 0
