"""Last known joint positions: the state file, the start-up check, ``hofto-hw zero set``."""

from __future__ import annotations

import math
import shutil
from pathlib import Path

import numpy as np
import pytest
import yaml

from hofto_hw.cli import main
from hofto_hw.errors import UserError
from hofto_hw.runtime.positions import (
    LastPositions,
    check_positions,
    load_positions,
    save_positions,
    turn_bounds,
)
from tests.conftest import CONFIGS

JOINTS = ["j1", "j2"]


def test_state_file_round_trip_and_atomic_replace(tmp_path: Path) -> None:
    path = tmp_path / "last_positions.yaml"
    save_positions(path, LastPositions(JOINTS, np.array([0.1, -0.2]), [0, 12]))
    save_positions(path, LastPositions(JOINTS, np.array([0.3, -0.4]), [0, 12], at_rest=False))
    back = load_positions(path)
    assert back is not None and back.joints == JOINTS
    assert np.allclose(back.positions, [0.3, -0.4]) and back.zero_offsets == [0, 12]
    assert not back.at_rest
    assert [p.name for p in tmp_path.iterdir()] == ["last_positions.yaml"]  # no temp left
    assert load_positions(tmp_path / "none.yaml") is None


def test_corrupt_state_file_is_one_line(tmp_path: Path) -> None:
    path = tmp_path / "p.yaml"
    path.write_text("format: something else\n")
    with pytest.raises(UserError, match=r"p.yaml: not a hofto-hw positions file"):
        load_positions(path)


def test_a_lost_turn_is_refused_naming_joint_stored_and_read(tmp_path: Path) -> None:
    last = LastPositions(JOINTS, np.array([0.5, -1.0]), [0, 0])
    bounds = turn_bounds([100.0, 100.0])  # half a motor turn at the joint: 0.0314 rad
    check_positions(last, JOINTS, np.array([0.51, -1.02]), bounds, tmp_path / "p.yaml")
    lost = -1.0 + 2 * math.pi / 100.0  # one motor turn through the 100:1 gearbox
    with pytest.raises(UserError) as info:
        check_positions(last, JOINTS, np.array([0.5, lost]), bounds, tmp_path / "p.yaml")
    msg = str(info.value)
    assert msg.startswith("j2: position -0.93717 rad read at start-up, -1.00000 rad stored")
    assert "\n" not in msg


def test_start_up_on_the_bus_refuses_a_lost_turn_before_enabling(er3a_config, tmp_path) -> None:
    from drivers.cia402.state_machine import State
    from hofto_hw.runtime.compose import build_bus, check_start_positions

    bus, group = build_bus(er3a_config, "sim")
    group.cycle()
    joints = list(er3a_config.robot.joints)
    path = tmp_path / "last_positions.yaml"
    stored = group.q.copy()
    save_positions(path, LastPositions(joints, stored, [0] * 6))
    check_start_positions(er3a_config, bus, group, path)  # same positions: accepted
    stored[3] += 2 * math.pi / er3a_config.bus.drives[3].gear_ratio  # the battery was changed
    save_positions(path, LastPositions(joints, stored, [0] * 6))
    with pytest.raises(UserError, match=rf"^{joints[3]}: position .* stored at the last shutdown"):
        check_start_positions(er3a_config, bus, group, path)
    assert not (group.states == State.OPERATION_ENABLED).any()


@pytest.fixture
def config(tmp_path: Path) -> Path:
    shutil.copytree(CONFIGS / "er3a", tmp_path / "er3a")
    shutil.copy(CONFIGS / "er3a.yaml", tmp_path / "er3a.yaml")
    return tmp_path / "er3a.yaml"


def _positions(path: Path, q1: float, **kw) -> None:
    import hofto_hw.config as c

    joints = list(c.load_config(CONFIGS / "er3a.yaml").robot.joints)
    save_positions(path, LastPositions(joints, np.array([0.0, q1, 0, 0, 0, 0]), [0] * 6, **kw))


def test_zero_set_round_trip(config: Path, tmp_path: Path, capsys) -> None:
    from drivers.cia402.units import AxisScaling, Scaling
    from hofto_hw.config import load_config

    pos = tmp_path / "pos.yaml"
    _positions(pos, 0.3)
    before = config.read_text()
    d0 = load_config(config).bus.drives[1]
    counts = np.array(
        [d0.zero_offset + d0.direction * 0.3 * d0.counts_per_rev * d0.gear_ratio / (2 * math.pi)]
    )
    args = ["zero", "set", "--config", config, "--joint", "2", "--at", "0.1", "--positions", pos]
    assert main([str(a) for a in args]) == 0
    out = capsys.readouterr().out
    assert "zero_offset 0 ->" in out
    cfg = load_config(config)
    d = cfg.bus.drives[1]
    q = np.zeros(1)
    Scaling([AxisScaling.from_config(d)]).position_to_si(counts, q)
    assert q[0] == pytest.approx(0.1, abs=1e-6)  # the same encoder count now reads 0.1 rad
    assert [x.zero_offset for i, x in enumerate(cfg.bus.drives) if i != 1] == [0] * 5
    # only that value changed in the text; the old file kept; the change logged
    backups = list(tmp_path.glob("er3a.yaml.bak-*"))
    assert len(backups) == 1 and backups[0].read_text() == before
    assert len(config.read_text().splitlines()) == len(before.splitlines())
    assert "# six CiA-402 servo drives" in config.read_text()
    assert "zero_offset 0 ->" in (tmp_path / "zero_changes.log").read_text()
    last = load_positions(pos)
    assert last is not None and last.positions[1] == pytest.approx(0.1)
    assert last.zero_offsets[1] == d.zero_offset


@pytest.mark.parametrize(
    ("kw", "argv", "needle"),
    [
        ({"latched": ["collision"]}, [], "a fault was latched at the last shutdown (collision)"),
        ({"at_rest": False}, [], "the arm was moving at the last shutdown"),
        ({}, ["--at", "nan"], "--at must be a finite angle"),
        ({}, ["--joint", "elbow"], "--joint 'elbow': not one of"),
        (None, [], "no positions stored"),
    ],
    ids=["latched", "moving", "nan", "joint", "no-file"],
)
def test_zero_set_refusals_write_nothing(config, tmp_path, capsys, kw, argv, needle) -> None:
    pos = tmp_path / "pos.yaml"
    if kw is not None:
        _positions(pos, 0.3, **kw)
    before = config.read_text()
    base = {"--joint": "2", "--at": "0.1"}
    for k, v in zip(argv[::2], argv[1::2], strict=True):
        base[k] = v
    args = ["zero", "set", "--config", str(config), "--positions", str(pos)]
    for k, v in base.items():
        args += [k, v]
    assert main(args) != 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and needle in err[0], err
    assert config.read_text() == before and not list(tmp_path.glob("*.bak-*"))


def test_zero_set_adds_the_key_to_a_flow_mapping(config: Path) -> None:
    from hofto_hw.runtime.zero_offset import _with_zero_offset

    text = config.read_text()
    new = _with_zero_offset(text, 4, 1234, config)
    doc = yaml.safe_load(new)
    assert doc["bus"]["drives"][4]["zero_offset"] == 1234
    again = _with_zero_offset(new, 4, -5, config)
    assert yaml.safe_load(again)["bus"]["drives"][4]["zero_offset"] == -5


def test_axes_state_shows_sto_and_brake_per_axis(er3a_config) -> None:
    from types import SimpleNamespace

    from hofto_hw.runtime.axes import axes_state, axes_text
    from hofto_hw.runtime.compose import build_bus

    bus, group = build_bus(er3a_config, "sim")
    system = SimpleNamespace(group=group, bus=bus, cfg=er3a_config)
    bus.drives.set_safe_torque_off(2, True)
    bus.drives.configure_brake(1, 0.05, 0.05, 100.0)
    group.cycle()
    axes = axes_state(system)
    assert [a["sto"] for a in axes] == [False, False, True, False, False, False]
    assert all(a["brake"] == "closed" for a in axes)  # power stage off everywhere
    assert "joint_3 ACTIVE/closed" in axes_text(axes)
    bus.drives.set_safe_torque_off(2, False)
    group.enable()
    for _ in range(round(0.06 / bus.cycle_time) + 2):
        group.cycle()
    axes = axes_state(system)
    assert [a["brake"] for a in axes] == ["open"] * 6 and not any(a["sto"] for a in axes)
    bus.close()
