"""The shipped native library is loaded only when it fits: built against the installed
pinocchio's major.minor, and (in a source checkout) from the dynamics.cpp beside it."""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

import pinocchio
import pytest

from hofto_hw.model import native


def _installed() -> tuple[int, int, int]:
    major, minor, patch = (int(x) for x in pinocchio.__version__.split(".")[:3])
    return major, minor, patch


def test_another_pinocchio_minor_version_is_refused_in_one_line(tmp_path: Path) -> None:
    major, minor, _ = _installed()
    why = native.mismatch((major, minor + 1, 0), "0" * 64, None)
    assert f"built against pinocchio {major}.{minor + 1}.0" in why
    assert f"pinocchio {pinocchio.__version__} is installed" in why and "\n" not in why
    assert native.mismatch((major + 1, minor, 0), "0" * 64, None)


def test_same_minor_version_and_source_load(tmp_path: Path) -> None:
    major, minor, _ = _installed()
    source = tmp_path / "dynamics.cpp"
    source.write_text("// the source\n")
    sha = hashlib.sha256(source.read_bytes()).hexdigest()
    assert native.mismatch((major, minor, 99), sha, source) == ""
    assert native.mismatch((major, minor, 0), sha, None) == ""  # a wheel ships no source


def test_an_edited_source_refuses_the_stale_library(tmp_path: Path) -> None:
    major, minor, _ = _installed()
    source = tmp_path / "dynamics.cpp"
    source.write_text("// edited after the build\n")
    why = native.mismatch((major, minor, 0), "0" * 64, source)
    assert "changed since the library was built" in why and "pip install -e ." in why


def test_the_checkout_has_its_library_built_from_its_source() -> None:
    """``pip install -e .`` built it in place; its recorded hash is dynamics.cpp's."""
    if not native.ready():
        if os.environ.get("CI"):
            pytest.fail(f"native dynamics unavailable in CI: {native.unavailable_reason()}")
        pytest.skip(f"native dynamics unavailable: {native.unavailable_reason()}")
    lib = native.library_path()
    assert lib is not None and lib.parent == Path(native.__file__).parent
    assert native.built_against().split(".")[:2] == pinocchio.__version__.split(".")[:2]
