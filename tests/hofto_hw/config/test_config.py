"""Config loading: good files load, bad files fail naming file, field and value."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from hofto_hw.config import load_config
from hofto_hw.errors import ConfigError, ModelError
from hofto_hw.model import RobotModel

ROOT = Path(__file__).resolve().parents[3]


def _write(tmp_path: Path, data: dict) -> Path:
    path = tmp_path / "cfg.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


@pytest.fixture()
def base() -> dict:
    data = yaml.safe_load((ROOT / "configs" / "er3a.yaml").read_text())
    data["robot"]["urdf"] = str(ROOT / "configs" / "er3a" / "er3a.urdf")
    return data


def test_shipped_configs_load():
    for name in ("er3a.yaml", "ur10e.yaml"):
        cfg = load_config(ROOT / "configs" / name)
        assert len(cfg.robot.joints) == 6
        assert cfg.robot.urdf.is_file()


def test_sigma_out_of_range_names_field(tmp_path, base):
    base["observers"]["hofto"].pop("powers")
    base["observers"]["hofto"]["sigma"] = -0.3  # n = 2: must be in (-0.25, 0)
    with pytest.raises(ConfigError) as err:
        load_config(_write(tmp_path, base))
    assert "observers.hofto" in str(err.value) and "sigma" in str(err.value)
    assert "cfg.yaml" in str(err.value)


def test_order_below_one(tmp_path, base):
    base["observers"]["hofto"]["order"] = 0
    with pytest.raises(ConfigError, match=r"observers\.hofto\.hofto\.order.*got 0"):
        load_config(_write(tmp_path, base))


def test_wrong_number_of_gains(tmp_path, base):
    base["observers"]["hofto"]["gains"] = base["observers"]["hofto"]["gains"][:3]
    with pytest.raises(ConfigError, match="gains has 3 rows, expected n \\+ 2 = 4"):
        load_config(_write(tmp_path, base))
    base2 = yaml.safe_load((ROOT / "configs" / "er3a.yaml").read_text())
    base2["robot"]["urdf"] = base["robot"]["urdf"]
    base2["observers"]["eso"]["k1"] = [8.0, 8.0]
    with pytest.raises(ConfigError, match=r"observers\.eso\.k1 has 2 entries, expected 6"):
        load_config(_write(tmp_path, base2))


def test_negative_gain_names_index_and_value(tmp_path, base):
    base["observers"]["momentum"]["gain"][2] = -5.0
    with pytest.raises(ConfigError) as err:
        load_config(_write(tmp_path, base))
    text = str(err.value)
    assert "observers.momentum.momentum.gain[2]" in text and "-5.0" in text


def test_missing_urdf(tmp_path, base):
    base["robot"]["urdf"] = "nowhere/robot.urdf"
    with pytest.raises(ConfigError, match=r"robot\.urdf: file not found"):
        load_config(_write(tmp_path, base))


def test_unknown_joint_is_named(tmp_path, base):
    base["robot"]["joints"][3] = "joint_four"
    cfg = load_config(_write(tmp_path, base))
    with pytest.raises(ModelError, match=r"robot\.joints\[3\]: joint 'joint_four' is not in"):
        RobotModel.from_config(cfg.robot)


def test_unknown_key_and_bad_yaml(tmp_path, base):
    base["loop"]["rate"] = 1000
    with pytest.raises(ConfigError, match=r"loop\.rate: Extra inputs are not permitted"):
        load_config(_write(tmp_path, base))
    bad = tmp_path / "bad.yaml"
    bad.write_text("robot: [unclosed\n")
    with pytest.raises(ConfigError, match=r"bad\.yaml: line \d+ column \d+: not valid YAML"):
        load_config(bad)
    with pytest.raises(ConfigError, match="config file not found"):
        load_config(tmp_path / "absent.yaml")


def test_sigma_gives_eq17_powers(tmp_path, base):
    h = base["observers"]["hofto"]
    h.pop("powers")
    h["sigma"] = -0.2
    cfg = load_config(_write(tmp_path, base))
    assert cfg.observers["hofto"].stage_powers() == pytest.approx([0.8, 0.6, 0.4, 0.2])


def test_read_yaml_names_file_and_kind_for_every_reader(tmp_path):
    from hofto_hw.config.loader import read_yaml
    from hofto_hw.identify.data import load_column_map
    from hofto_hw.model.parameters import read_parameters
    from hofto_hw.replay.thresholds import read_thresholds

    bad = tmp_path / "broken.yaml"
    bad.write_text("a: [1, 2\n")
    with pytest.raises(ConfigError, match=r"broken\.yaml: line 2 column 1: not valid YAML"):
        read_yaml(bad, "column map")
    with pytest.raises(ModelError, match=r"absent\.yaml: parameters file not found"):
        read_yaml(tmp_path / "absent.yaml", "parameters file", ModelError)
    for reader, err in (
        (load_column_map, ConfigError),
        (read_thresholds, ConfigError),
        (read_parameters, ModelError),
    ):
        with pytest.raises(err, match=r"broken\.yaml: line 2 column 1: not valid YAML"):
            reader(bad)


@pytest.mark.parametrize(
    ("content", "words"),
    [
        (b"a: 1\nb: '\x07x'\n", r"line 2 column 5: not valid YAML: control character U\+0007"),
        (b"a: " + b"[" * 3000 + b"\n", "not valid YAML: nested too deeply"),
        (b"42\n", "expected a mapping .* got a single value 42"),
        (b"a: 1\n\xff\xfe", r"not UTF-8 text at byte 5 \(line 2, byte 0xff\)"),
    ],
)
def test_read_yaml_one_line_for_each_kind_of_damage(tmp_path, content, words):
    from hofto_hw.config.loader import read_yaml

    path = tmp_path / "f.yaml"
    path.write_bytes(content)
    with pytest.raises(ConfigError, match=rf"^{path}: .*{words}") as err:
        read_yaml(path, "column map")
    assert len(str(err.value).splitlines()) == 1


def test_read_yaml_accepts_a_bom_and_names_a_folder(tmp_path):
    from hofto_hw.config.loader import read_yaml

    path = tmp_path / "bom.yaml"
    path.write_bytes("\ufeffname: caf\u00e9\n".encode())
    assert read_yaml(path, "column map") == {"name": "caf\u00e9"}
    with pytest.raises(ConfigError, match=rf"^{tmp_path}: is a folder, not a column map$"):
        read_yaml(tmp_path, "column map")


@pytest.mark.parametrize("value", [-1, 1.5, "fast", float("nan"), 2_000_000])
def test_cpu_latency_out_of_range_or_not_an_integer_names_field(tmp_path, base, value):
    base["loop"]["cpu_latency_us"] = value
    with pytest.raises(ConfigError) as err:
        load_config(_write(tmp_path, base))
    text = str(err.value)
    assert "loop.cpu_latency_us" in text and "cfg.yaml" in text and len(text.splitlines()) == 1


def test_cpu_latency_null_requests_none(tmp_path, base):
    assert load_config(ROOT / "configs" / "er3a.yaml").loop.cpu_latency_us == 0
    base["loop"]["cpu_latency_us"] = None
    assert load_config(_write(tmp_path, base)).loop.cpu_latency_us is None
