"""Every command that reads a YAML file answers a damaged one with one line naming the file.

Kinds of damage: binary, not UTF-8, empty, truncated (YAML cut inside a flow list; a file cut
inside a UTF-8 character), valid YAML that is not a mapping, a duplicate key and an alias
(the one safe reader refuses both, see hofto_hw/config/loader.py). Each is tried as a config
(``config check``), a parameters file (``replay``), a thresholds file (``thresholds check``)
and a column map (``identify --columns``).
"""

from __future__ import annotations

import re
from collections.abc import Callable
from pathlib import Path

import pytest

from hofto_hw.cli import main

ROOT = Path(__file__).resolve().parents[3]
CONFIGS = ROOT / "configs"
CSV = ROOT / "tests" / "data" / "ur10e" / "push_pose_1_rows100-600.csv"
PARAMS = CONFIGS / "ur10e" / "parameters.yaml"


def _truncated(good: Path) -> bytes:
    """``good`` cut inside its last ``key: [...]`` flow list (an unclosed list)."""
    text = good.read_text()
    return text[: text.rindex(": [") + 6].encode()


def _duplicate_key(good: Path) -> bytes:
    """``good`` with its first top-level key given again at the end (YAML's last would win)."""
    key = re.search(r"^([A-Za-z_]\w*):", good.read_text(), re.MULTILINE)
    assert key is not None
    return good.read_bytes() + f"\n{key.group(1)}: 0\n".encode()


#: kind -> (bytes of the damaged file from the good file of its role, words the error says)
DAMAGE: dict[str, tuple[Callable[[Path], bytes], str]] = {
    "binary": (lambda good: bytes(range(256)) * 4, "is a binary file"),
    "latin-1": (
        lambda good: good.read_bytes().replace(b"\n", "\n# caf\u00e9\n".encode("latin-1"), 1),
        "not UTF-8 text at byte",
    ),
    "empty": (lambda good: b"", "is empty"),
    "comments only": (lambda good: b"# nothing here\n\n", "is empty"),
    "truncated": (_truncated, "the file ends early: truncated?"),
    "cut in a character": (
        lambda good: good.read_bytes() + "# \u00e9".encode()[:-1],
        "ends inside a UTF-8 character",
    ),
    "a list": (lambda good: b"- 1\n- 2\n", "expected a mapping"),
    "duplicate key": (_duplicate_key, "duplicate key"),
    "alias": (
        lambda good: good.read_bytes() + b"\nanchored: &here 1\naliased: *here\n",
        "alias *here refused",
    ),
}

#: role -> (good file of that role, argv with the damaged file at BAD)
ROLES: dict[str, tuple[Path, list[str]]] = {
    "config": (CONFIGS / "er3a.yaml", ["config", "check", "BAD"]),
    "parameters": (PARAMS, ["replay", "BAD", str(CSV)]),
    "thresholds": (
        CONFIGS / "ur10e" / "thresholds.yaml",
        ["thresholds", "check", "--params", str(PARAMS), "--thresholds", "BAD", str(CSV)],
    ),
    "column map": (
        CONFIGS / "ur10e" / "columns_31.yaml",
        ["identify", "--config", str(CONFIGS / "ur10e.yaml"), "--columns", "BAD", "-o", "OUT"]
        + [str(CSV)],
    ),
}


@pytest.mark.parametrize("role", list(ROLES))
@pytest.mark.parametrize("kind", list(DAMAGE))
def test_damaged_yaml_is_one_line_naming_the_file(
    role: str, kind: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    good, argv = ROLES[role]
    make, words = DAMAGE[kind]
    bad = tmp_path / f"damaged {role}.yaml"
    bad.write_bytes(make(good))
    out = tmp_path / "out.yaml"
    code = main([str(bad) if a == "BAD" else str(out) if a == "OUT" else a for a in argv])
    err = capsys.readouterr().err.strip()
    assert code == 2, err
    assert len(err.splitlines()) == 1, err
    assert "Traceback" not in err
    assert str(bad) in err and words in err, err
    assert not out.exists()


def test_the_damaged_files_come_from_good_ones(capsys: pytest.CaptureFixture[str]) -> None:
    # the same commands accept the undamaged files (else the test above proves nothing)
    assert main(["config", "check", str(ROLES["config"][0])]) == 0
    assert PARAMS.read_bytes().startswith(_truncated(PARAMS))


@pytest.mark.parametrize(
    ("old", "new", "field"),
    [
        ("smooth_velocity: ", "smooth_velocity: .inf #", "model.friction.smooth_velocity"),
        ("    value: ", "    value: .nan #", "base.parameters[0].value"),
    ],
)
def test_non_finite_numbers_in_a_parameters_file_are_one_line(
    old: str, new: str, field: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    text = PARAMS.read_text()
    assert old in text
    bad = tmp_path / "parameters.yaml"
    bad.write_text(text.replace(old, new, 1))
    code = main(["replay", str(bad), str(CSV)])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1, err
    assert f"{bad}: {field}: contains NaN or inf" in err
