"""tools/pulse_detection.py --json: the report is JSON even when a file's monitor trips (the
tripped joints were numpy integers, which json refused with a traceback)."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_the_json_report_names_the_tripped_joints_as_numbers(capsys) -> None:
    path = ROOT / "tools" / "pulse_detection.py"
    spec = importlib.util.spec_from_file_location("pulse_detection_tool", path)
    tool = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(tool)
    data = ROOT / "tests" / "data" / "ur10e" / "push_pose_1_rows100-600.csv"
    args = [str(ROOT / "configs" / "ur10e" / f) for f in ("parameters.yaml", "thresholds.yaml")]
    argv = [*args, str(data), "--observer", "momentum", "--amplitudes", "20", "--rounds", "1"]
    assert tool.main([*argv, "--json"]) == 0
    res = json.loads(capsys.readouterr().out)
    (obs,) = res["observers"]
    tripped = obs["false_alarm_joints"][data.name]
    # the recording holds a person's pushes: the monitor trips on some joints, 1-based
    assert tripped and all(isinstance(j, int) and 1 <= j <= 6 for j in tripped)
    assert sum(obs["false_alarms"]) == len(tripped)
