"""The hofto-hw command: config schema/check and the demo, as a user runs them."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[3]


def run_cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "hofto_hw.cli", *args],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=300,
    )


def test_config_schema_is_json_schema():
    out = run_cli("config", "schema")
    assert out.returncode == 0, out.stderr
    schema = json.loads(out.stdout)
    assert "robot" in schema["properties"] and "observers" in schema["properties"]


def test_config_check_good_and_bad(tmp_path):
    ok = run_cli("config", "check", "configs/er3a.yaml", "configs/ur10e.yaml")
    assert ok.returncode == 0, ok.stderr
    assert "configs/er3a.yaml: ok" in ok.stdout
    bad = tmp_path / "bad.yaml"
    text = (ROOT / "configs" / "er3a.yaml").read_text().replace("order: 2", "order: 0")
    bad.write_text(text.replace("urdf: er3a/er3a.urdf", f"urdf: {ROOT}/configs/er3a/er3a.urdf"))
    out = run_cli("config", "check", str(bad))
    assert out.returncode == 2
    assert "observers.hofto.hofto.order" in out.stderr and "Traceback" not in out.stderr


@pytest.mark.slow
def test_demo_json(tmp_path):
    out = run_cli("demo", "--json", "--duration", "6", "--plot", str(tmp_path / "fig.png"))
    assert out.returncode == 0, out.stderr
    report = json.loads(out.stdout)
    for block in ("paper_gains", "matched_bandwidth"):
        for name in ("hofto", "eso", "dob"):
            idx = report[block]["indices"][name]
            assert set(idx) == {"offset", "ma", "rms"} and len(idx["rms"]) == 6
    assert len(report["paper_rms_ratios"]["hofto/eso"]) == 6
    assert (tmp_path / "fig.png").stat().st_size > 10_000
