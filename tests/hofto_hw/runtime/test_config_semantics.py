"""Settings that would stop the arm at once, or quietly change what runs, are refused (or
said) at load: a home outside the monitored joint range, a demo path that leaves it or needs
more speed or torque than the limits allow, an empty ``loop.observers``, a ``--duration``
shorter than one tick, ``--interface`` on the simulated bus.

Before: a path 100 times too large ran into a torque-limit stop after 54 ms, a home outside
the limits into a position-limit stop in the first tick, ``loop.observers: {}`` fell back
silently to the offline gains (HOFTO detected in 67 ms instead of 5 ms), ``--duration
1e-9`` said "ran 0 ticks" with exit 0 and ``--interface`` was ignored on the sim bus.
"""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml
from support.cli import one_line_error, run_limited

from hofto_hw.cli import main
from hofto_hw.config.loader import load_config
from hofto_hw.errors import ConfigError

ROOT = Path(__file__).resolve().parents[3]
ER3A = ROOT / "configs" / "er3a.yaml"


def _variant(tmp_path: Path, edit) -> Path:
    data = yaml.safe_load(ER3A.read_text())
    edit(data)
    data["robot"]["urdf"] = str(ER3A.parent / data["robot"]["urdf"])
    path = tmp_path / "er3a.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def _scaled_path(d: dict) -> None:
    d["run"]["path"]["amplitude"] = [100 * a for a in d["run"]["path"]["amplitude"]]


def _set_home(d: dict) -> None:
    d["robot"]["home"][1] = 4.0  # rad: beyond joint 2's range


def _fast_path(d: dict) -> None:
    d["run"]["path"]["period"] = [0.5] * 6  # 0.5 rad at 2 Hz: 6 rad/s wanted on joint 2


def _weak_drives(d: dict) -> None:
    d["safety"].setdefault("limits", {})["torque"] = [200.0, 5.0, 200.0, 200.0, 200.0, 200.0]


@pytest.mark.parametrize(
    ("edit", "words"),
    [
        (_scaled_path, "run.path.amplitude[0] = 80 rad (joint 1, joint_1) moves the joint"),
        (_set_home, "robot.home[1] = 4 rad (joint 2, joint_2) is outside"),
        (_fast_path, "rad/s, above the velocity limit"),
        (_weak_drives, "above the torque limit 5 N·m"),
    ],
    ids=["path x100", "home", "speed", "torque"],
)
def test_motion_outside_the_limits_is_refused_by_config_check(edit, words, tmp_path, capsys):
    path = _variant(tmp_path, edit)
    code = main(["config", "check", str(path)])
    one_line_error(code, capsys.readouterr().err, str(path), words)


def test_run_refuses_a_path_x100_before_the_arm_moves(tmp_path: Path) -> None:
    path = _variant(tmp_path, _scaled_path)
    argv = ["run", "--config", str(path), "--clock", "sim", "--duration", "0.5", "--no-log"]
    code, out, err, _ = run_limited(argv, timeout=300)
    assert code == 2, err
    assert "Traceback" not in err and "run.path.amplitude[0] = 80 rad" in err, err
    assert out == ""  # no summary: nothing ran


def test_empty_loop_observers_is_refused(tmp_path: Path) -> None:
    path = _variant(tmp_path, lambda d: d["loop"].update(observers={}))
    with pytest.raises(ConfigError, match=r"loop\.observers: Value error, empty: name the obs"):
        load_config(path)


def test_run_says_which_observer_gains_the_loop_runs(tmp_path: Path) -> None:
    def only_hofto(d: dict) -> None:
        d["loop"]["observers"].pop("momentum")

    path = _variant(tmp_path, only_hofto)
    argv = ["run", "--config", str(path), "--clock", "sim", "--duration", "0.05", "--no-log"]
    code, out, err, _ = run_limited([*argv, "--no-collision"], timeout=300)
    assert code == 0, err
    assert (
        "hofto-hw run: loop observers hofto (loop.observers), momentum (observers: the "
        "offline gains)"
    ) in err


@pytest.mark.parametrize(
    ("argv", "words"),
    [
        (["--duration", "1e-9"], "--duration: 1e-09 s is less than one tick"),
        (["--interface", "eth0"], "--interface eth0: does not apply to bus.transport sim"),
    ],
    ids=["duration", "interface"],
)
def test_run_options_that_cannot_apply_are_refused(argv, words, capsys) -> None:
    code = main(["run", "--config", str(ER3A), "--clock", "sim", "--no-log", *argv])
    out, err = capsys.readouterr()
    one_line_error(code, err, words)
    assert out == ""


def test_run_names_a_drive_without_torque_offset_at_start_up() -> None:
    # configs/er3a_mixed.yaml: joint 5 runs maxon_epos4 (no 0x60B2; fallback
    # target_torque_in_cst), the other five map the torque offset
    path = ROOT / "configs" / "er3a_mixed.yaml"
    argv = ["run", "--config", str(path), "--clock", "sim", "--duration", "0.05", "--no-log"]
    code, _out, err, _ = run_limited([*argv, "--no-collision"], timeout=300)
    assert code == 0, err
    notes = [line for line in err.splitlines() if "no torque offset" in line]
    assert notes == [
        "hofto-hw run: axis 4 (joint_5): no torque offset 0x60B2 mapped: the gravity "
        "feed-forward reaches this drive only through the target torque in CST; in CSP this "
        "joint runs without it"
    ], err
