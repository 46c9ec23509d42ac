"""``safety.profiles``: named sets checked at load time against the bounds the file sets."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from hofto_hw.config.loader import load_config
from hofto_hw.errors import ConfigError

CONFIG = Path(__file__).resolve().parents[3] / "configs" / "er3a.yaml"


def _with(tmp_path: Path, profiles: dict) -> Path:
    data = yaml.safe_load(CONFIG.read_text())
    data["robot"]["urdf"] = str((CONFIG.parent / data["robot"]["urdf"]).resolve())
    data["safety"]["profiles"] = profiles
    out = tmp_path / "p.yaml"
    out.write_text(yaml.safe_dump(data))
    return out


def test_the_shipped_profiles_load() -> None:
    p = load_config(CONFIG).safety.profiles
    assert p is not None and p.active == "normal"
    assert set(p.sets) == {"normal", "reduced", "contact-task"}
    assert p.sets["contact-task"].drag_factors() == (2.0, 2.0, 0.4)
    assert p.sets["normal"].drag_factors() == (1.0, 1.0, 1.0)


@pytest.mark.parametrize(
    ("profiles", "needle"),
    [
        (
            {"active": "a", "bounds": {"collision_scale_max": 1.2},
             "sets": {"a": {"collision_scale": 1.5}}},
            "sets.a.collision_scale: 1.5 is above bounds.collision_scale_max = 1.2",
        ),
        (
            {"active": "a", "bounds": {"speed_scale_max": 0.5},
             "sets": {"a": {"speed_scale": 0.8}}},
            "sets.a.speed_scale: 0.8 is above bounds.speed_scale_max = 0.5",
        ),
        ({"active": "a", "sets": {"a": {"speed_scale": 1.5}}}, "speed_scale"),  # robot's limit
        ({"active": "a", "bounds": {"speed_scale_max": 2.0}, "sets": {"a": {}}}, "speed_scale_max"),
        ({"active": "b", "sets": {"a": {}}}, "active: 'b' is not one of sets (a)"),
        ({"active": "a", "sets": {"a": {"collision_scale": -1}}}, "collision_scale"),
        ({"active": "a", "sets": {"a": {"collision_scale": ".nan"}}}, "collision_scale"),
        (
            {"active": "a", "bounds": {"drag_speed_scale_max": 0.5},
             "sets": {"a": {"drag_speed_scale": 0.8}}},
            "sets.a.drag_speed_scale: 0.8 is above bounds.drag_speed_scale_max = 0.5",
        ),
        ({"active": "a", "sets": {"a": {"drag_speed_scale": 1.2}}}, "drag_speed_scale"),
        (
            {"active": "a", "bounds": {"drag_mass_scale_min": 0.8},
             "sets": {"a": {"drag_mass_scale": 0.5}}},
            "sets.a.drag_mass_scale: 0.5 is below bounds.drag_mass_scale_min = 0.8",
        ),
        (
            {"active": "a", "bounds": {"drag_damping_scale_min": 1.0},
             "sets": {"a": {"drag_damping_scale": 0.9}}},
            "sets.a.drag_damping_scale: 0.9 is below bounds.drag_damping_scale_min = 1.0",
        ),
        (  # B_a x5 with M_a x0.05: explicit Euler of the admittance would ring at 1 kHz
            {"active": "a", "bounds": {"drag_mass_scale_min": 0.01},
             "sets": {"a": {"drag_mass_scale": 0.05, "drag_damping_scale": 5.0}}},
            "sets.a (drag factors): mass/damping: k·B_a·dt/M_a",
        ),
    ],
)  # fmt: skip
def test_a_profile_beyond_its_bounds_is_one_line(tmp_path: Path, profiles, needle: str) -> None:
    with pytest.raises(ConfigError) as e:
        load_config(_with(tmp_path, profiles))
    msg = str(e.value)
    assert "\n" not in msg and "safety.profiles" in msg and needle in msg, msg
