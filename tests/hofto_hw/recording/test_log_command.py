"""`hofto-hw log info` and `hofto-hw log recover` on good, truncated and bad files."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from hofto_hw.cli import main
from hofto_hw.recording.writer import write_joint_states

N = 20_000


@pytest.fixture()
def log(tmp_path: Path) -> Path:
    t = np.arange(N) * 1e-3
    q = np.random.default_rng(0).normal(size=(N, 6))  # incompressible: several 1 MiB chunks
    path = tmp_path / "run.mcap"
    write_joint_states(path, t, q, q, q)
    return path


def test_info_lists_topics_counts_and_duration(log, capsys):
    assert main(["log", "info", str(log), "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["complete"] is True
    assert d["topics"]["/joint_states"] == {"type": "sensor_msgs/msg/JointState", "messages": N}
    assert d["duration"] == pytest.approx((N - 1) * 1e-3)
    assert d["size"] == log.stat().st_size


def test_info_and_recover_of_a_truncated_file(log, tmp_path, capsys):
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(log.read_bytes()[: log.stat().st_size // 2])
    assert main(["log", "info", str(cut)]) == 0
    assert "INCOMPLETE" in capsys.readouterr().out
    assert main(["log", "recover", str(cut)]) == 0
    assert "truncated" in capsys.readouterr().out
    fixed = tmp_path / "cut.recovered.mcap"
    assert main(["log", "info", str(fixed), "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["complete"] is True
    assert 0 < d["topics"]["/joint_states"]["messages"] < N // 2 + 4000
    # the default output exists now: refuse rather than overwrite what the user did not name
    before = fixed.read_bytes()
    assert main(["log", "recover", str(cut)]) == 2
    assert "-o" in capsys.readouterr().err
    assert fixed.read_bytes() == before


@pytest.mark.parametrize(
    ("content", "message"),
    [
        (bytes(range(256)) * 20, "not an MCAP file"),
        (b"", "empty"),
        (b"\x89MCAP0\r\n" + b"\xff" * 100, "no complete message"),
    ],
)
def test_recover_refuses_non_mcap_input_with_one_line(tmp_path, capsys, content, message):
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(content)
    assert main(["log", "recover", str(bad)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and str(bad) in err and message in err
    assert not (tmp_path / "bad.recovered.mcap").exists()
    assert bad.read_bytes() == content


def test_info_of_a_missing_file(tmp_path, capsys):
    assert main(["log", "info", str(tmp_path / "nope.mcap")]) == 2
    assert "not found" in capsys.readouterr().err
