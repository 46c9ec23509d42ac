"""hofto-hw's one compiled part, built when the package is built: the native dynamics library.

``hofto_hw/model/native/dynamics.cpp`` (pinocchio's algorithms behind plain C functions, called
by name from numba kernels) is compiled here against the headers of the ``pin``, ``cmeel-eigen``
and ``cmeel-boost`` wheels that ``[build-system] requires`` installs into the build environment
(their cmeel prefix), and ships inside the wheel as ``hofto_hw/model/native/_dynamics.so``.
The robot PC needs no compiler and builds nothing at run time. ``pip install -e .`` builds it
in place (next to dynamics.cpp); after editing dynamics.cpp run that again (the loader refuses
a library whose recorded source hash differs from the file beside it).

Why setuptools and not CMake: the library is one translation unit of header-only pinocchio
(no libpinocchio to link, no Python binding: ctypes and numba call its ``extern "C"``
functions), so a compiler call with two include folders is the whole build; pinocchio's CMake
config would add CMake, a find of Boost/urdfdom and a link to libpinocchio that nothing uses.

Everything else (metadata, dependencies, packages) is in pyproject.toml; this file adds the
extension and maps ``configs/`` into the package as ``hofto_hw.robot_configs``.
"""

from __future__ import annotations

import hashlib
import sys
from pathlib import Path

from setuptools import Extension, find_packages, setup
from setuptools.command.build_ext import build_ext

try:  # setuptools >= 70.1 has it; before, the wheel package's
    from setuptools.command.bdist_wheel import bdist_wheel
except ImportError:  # pragma: no cover
    from wheel.bdist_wheel import bdist_wheel

HERE = Path(__file__).resolve().parent
SOURCE = "hofto_hw/model/native/dynamics.cpp"

#: pinocchio's own compile definitions (its CMake config exports them); -O3: the algorithms ran
#: ~15 % faster than at -O2 (same numbers: no -ffast-math, no -march: the wheel runs on any
#: x86-64); -g0 after Python's own -g: debug info would make the library ~10x larger
FLAGS = [
    "-std=c++17",
    "-O3",
    "-g0",
    "-DNDEBUG",
    "-DBOOST_MPL_LIMIT_LIST_SIZE=30",
    "-DBOOST_MPL_LIMIT_VECTOR_SIZE=30",
    "-DBOOST_MPL_CFG_NO_PREPROCESSED_HEADERS",
    "-DBOOST_FUSION_INVOKE_MAX_ARITY=12",
]


HEADERS = (
    ("pinocchio/multibody.hpp", "pin"),
    ("eigen3/Eigen/Core", "cmeel-eigen"),
    ("boost/variant.hpp", "cmeel-boost"),
)


def header_prefix() -> Path:
    """The first cmeel prefix on the build's path that holds pinocchio's, Eigen's and Boost's
    headers (in include/), found without importing pinocchio. pip's isolated build environment
    has one (``[build-system] requires``, in its site-packages); the invoking venv's cmeel
    prefix comes first when it has all three (pip's isolation does not hide paths that .pth
    files added, as cmeel's do), and is skipped when it lacks one. The loader checks the
    pinocchio version the library records against the installed one either way."""
    seen: list[Path] = []
    for entry in map(Path, sys.path):
        # a path a cmeel .pth added (inside the prefix), or a site-packages holding one (pip's
        # build environment is on the path without its .pth files having run)
        inside = next((p for p in (entry, *entry.parents) if p.name == "cmeel.prefix"), None)
        for prefix in (inside, entry / "cmeel.prefix"):
            if prefix is None or prefix in seen or not prefix.is_dir():
                continue
            if not (prefix / "include" / HEADERS[0][0]).is_file():
                continue  # a cmeel prefix without pinocchio
            seen.append(prefix)
            if all((prefix / "include" / need).is_file() for need, _ in HEADERS):
                return prefix
    if not seen:
        raise SystemExit("hofto-hw build: pinocchio (the pin package) is not installed")
    inc = seen[0] / "include"
    missing = [pkg for need, pkg in HEADERS if not (inc / need).is_file()]
    raise SystemExit(
        f"hofto-hw build: {inc} lacks the headers of {', '.join(missing)} (and no other cmeel "
        "prefix on the path has them all)"
    )


class BuildNative(build_ext):
    """build_ext with the cmeel include folders and without Python's debug flags."""

    def build_extensions(self) -> None:
        self.force = True  # an object file of another pinocchio's headers is never reused
        inc = header_prefix() / "include"
        sha = hashlib.sha256((HERE / SOURCE).read_bytes()).hexdigest()
        for ext in self.extensions:
            ext.include_dirs += [str(inc), str(inc / "eigen3")]
            ext.define_macros.append(("HOFTO_DYN_SOURCE_SHA256", f'"{sha}"'))
        # Python's CFLAGS carry -g and -Wall; -g0 above turns the first off, this the noise
        self.compiler.compiler_so = [a for a in self.compiler.compiler_so if a != "-Wall"]
        super().build_extensions()

    def get_ext_filename(self, fullname: str) -> str:
        """``_dynamics.so``: not a Python extension module (no Python ABI; ctypes and numba
        load it), so not named for one interpreter (``.cpython-311-x86_64-linux-gnu.so``)."""
        return str(Path(*fullname.split("."))) + ".so"


class PlatformWheel(bdist_wheel):
    """The wheel's tag: ``py3-none-<platform>``. The native library uses no Python ABI (plain
    C functions loaded by ctypes/numba, nothing linked to libpython), so one wheel serves every
    Python 3 the package supports on that platform; it is still a platform wheel (x86-64
    Linux machine code), never a pure one."""

    def finalize_options(self) -> None:
        super().finalize_options()
        self.root_is_pure = False

    def get_tag(self) -> tuple[str, str, str]:
        _, _, platform = super().get_tag()
        return "py3", "none", platform


#: configs/ and its folders (URDFs, parameters, the unit...) as data-only packages: listed, so
#: that setuptools does not warn that each folder "would be ignored"
CONFIG_PACKAGES = [
    "hofto_hw.robot_configs",
    *(
        f"hofto_hw.robot_configs.{d.name}"
        for d in sorted((HERE / "configs").iterdir())
        if d.is_dir()
    ),
]

setup(
    packages=[*find_packages(include=["hofto_hw*", "drivers*", "safety*"]), *CONFIG_PACKAGES],
    package_data={
        "hofto_hw": ["py.typed"],
        "hofto_hw.robot_configs": ["*.yaml"],
        **{p: ["*"] for p in CONFIG_PACKAGES[1:]},
    },
    exclude_package_data={"hofto_hw.model.native": ["*.cpp"]},  # compiled into _dynamics.so
    package_dir={"hofto_hw.robot_configs": "configs"},
    ext_modules=[
        Extension(
            "hofto_hw.model.native._dynamics",
            sources=[SOURCE],
            language="c++",
            extra_compile_args=FLAGS,
            extra_link_args=["-s"],  # stripped: the symbols numba binds are dynamic ones
        )
    ],
    cmdclass={"build_ext": BuildNative, "bdist_wheel": PlatformWheel},
)
