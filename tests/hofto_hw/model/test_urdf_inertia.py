"""A URDF with a non-physical link gives one clear ModelError line (issue 7, bad input)."""

from __future__ import annotations

from pathlib import Path

import pytest

from hofto_hw.errors import ModelError
from hofto_hw.model import RobotModel

URDF = """<?xml version="1.0"?>
<robot name="tiny">
  <link name="base"/>
  <link name="arm">
    <inertial>
      <origin xyz="0.1 0 0"/>
      <mass value="{mass}"/>
      <inertia ixx="{ixx}" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/>
    </inertial>
  </link>
  <link name="tool"/>
  <joint name="j1" type="revolute">
    <parent link="base"/><child link="arm"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" effort="10" velocity="2"/>
  </joint>
  <joint name="tool_joint" type="fixed">
    <parent link="arm"/><child link="tool"/><origin xyz="0.2 0 0"/>
  </joint>
</robot>
"""


def _write(tmp_path: Path, mass: float, ixx: float) -> Path:
    path = tmp_path / "tiny.urdf"
    path.write_text(URDF.format(mass=mass, ixx=ixx))
    return path


def test_valid_urdf_loads(tmp_path: Path) -> None:
    model = RobotModel.from_urdf(_write(tmp_path, 1.0, 0.01), ["j1"], "tool")
    assert model.n == 1


@pytest.mark.parametrize(
    ("mass", "ixx", "what"),
    [(-1.0, 0.01, "mass"), (1.0, -0.01, "inertia"), (1.0, 0.5, "inertia")],
)
def test_nonphysical_link_is_one_clear_line(tmp_path: Path, mass, ixx, what) -> None:
    path = _write(tmp_path, mass, ixx)
    with pytest.raises(ModelError) as info:
        RobotModel.from_urdf(path, ["j1"], "tool")
    msg = str(info.value)
    assert "\n" not in msg
    assert str(path) in msg and "'arm'" in msg and what in msg
