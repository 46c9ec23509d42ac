"""The UR10e files that ship with the project: present (their absence fails, never skips)
and consistent with each other (thresholds calibrated with the shipped parameters file)."""

from __future__ import annotations

import hashlib
import re

import pytest

from hofto_hw.cli import main

from .conftest import PARAMS, PUSH, ROOT, THRESHOLDS


def test_shipped_thresholds_were_calibrated_with_the_shipped_parameters() -> None:
    from hofto_hw.model.parameters import read_parameters
    from hofto_hw.replay.thresholds import read_thresholds

    params = read_parameters(PARAMS)
    th = read_thresholds(THRESHOLDS)
    assert th.robot == params.robot == "ur10e"
    assert th.parameters is not None
    assert th.parameters.file == PARAMS.name
    assert th.parameters.sha256 == hashlib.sha256(PARAMS.read_bytes()).hexdigest()
    assert set(th.observers) >= {"momentum", "hofto", "dob", "eso", "direct"}


def test_replay_with_the_shipped_pair_has_no_provenance_warning(
    capsys: pytest.CaptureFixture[str],
) -> None:
    assert main(["replay", str(PARAMS), str(PUSH)]) == 0
    out = capsys.readouterr().out
    assert "contact episode(s)" in out
    assert "calibrated with another parameters file" not in out


def test_tests_do_not_skip_on_files_that_ship() -> None:
    """Only the external recordings (../shared/data) may make a test skip."""
    offenders = []
    for path in (ROOT / "tests").rglob("*.py"):
        if path.name == "test_shipped_files.py":
            continue
        for line in path.read_text().splitlines():
            if "pytest.skip" in line.replace("mark.skip", "pytest.skip") and re.search(
                r"\b(PARAMS|THRESHOLDS)\b|parameters\.yaml", line
            ):
                offenders.append(f"{path.relative_to(ROOT)}: {line.strip()}")
    assert offenders == []
