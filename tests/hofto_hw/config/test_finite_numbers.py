"""Every float of every file model is finite: inf, -inf, NaN and 1e999 are refused with the
file, the field path and the value (the loader's ``FILE: field.path: message (got VALUE)``)."""

from __future__ import annotations

import math
import typing
from collections.abc import Iterator
from pathlib import Path

import pytest
from pydantic import BaseModel, ValidationError

from hofto_hw.config.base import FileModel
from hofto_hw.config.loader import format_validation_error, load_config, parse_config
from hofto_hw.config.models import SystemConfig
from hofto_hw.errors import ConfigError
from hofto_hw.identify.data import ColumnMap, load_column_map
from hofto_hw.replay.thresholds import ThresholdsFile, read_thresholds

ROOT = Path(__file__).resolve().parents[3]
CONFIGS = ROOT / "configs"


def _models(annotation: object) -> Iterator[type[BaseModel]]:
    """Every pydantic model class named in ``annotation`` (through lists, unions, ...)."""
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        yield annotation
        for field in annotation.model_fields.values():
            yield from _models(field.annotation)
    for arg in typing.get_args(annotation):
        yield from _models(arg)


@pytest.mark.parametrize("top", [SystemConfig, ThresholdsFile, ColumnMap])
def test_every_file_model_derives_from_the_one_base(top: type[BaseModel]) -> None:
    models = set(_models(top))
    assert len(models) > 1 or top is ColumnMap
    assert [m.__name__ for m in models if not issubclass(m, FileModel)] == []


def _float_leaves(data: object, path: str = "") -> Iterator[tuple[str, list]]:
    """(path, [container, key]) of every float in nested dicts/lists."""
    items = data.items() if isinstance(data, dict) else enumerate(data)
    for key, value in items:
        here = f"{path}[{key}]" if isinstance(key, int) else f"{path}.{key}".lstrip(".")
        if isinstance(value, float):
            yield here, [data, key]
        elif isinstance(value, (dict, list)):
            yield from _float_leaves(value, here)


def _leaf_name(path: str) -> str:
    return path.rsplit(".", 1)[-1].split("[", 1)[0]


@pytest.mark.parametrize("bad", [math.inf, -math.inf, math.nan])
def test_every_float_of_the_shipped_config_refuses_non_finite(
    er3a_config: SystemConfig, bad: float
) -> None:
    data = er3a_config.model_dump(mode="python")
    leaves = list(_float_leaves(data))
    assert len(leaves) > 150  # gains, friction, drives, simulation, ...
    for path, (container, key) in leaves:
        good = container[key]
        container[key] = bad
        with pytest.raises(ConfigError) as err:
            parse_config(data, source="my.yaml")
        container[key] = good
        text = str(err.value)
        assert text.startswith("my.yaml: ") and len(text.splitlines()) == 1, (path, text)
        assert _leaf_name(path) in text and f"(got {bad!r})" in text, (path, text)
        assert "finite number" in text, (path, text)


def test_an_overflowing_literal_in_the_file_is_refused(tmp_path: Path) -> None:
    text = (CONFIGS / "er3a.yaml").read_text()
    text = text.replace("urdf: er3a/er3a.urdf", f"urdf: {CONFIGS / 'er3a' / 'er3a.urdf'}")
    path = tmp_path / "huge.yaml"
    head, _, tail = text.rpartition("gain: [30.0,")  # the top-level observers.momentum
    path.write_text(head + "gain: [1e999," + tail)
    with pytest.raises(ConfigError) as err:
        load_config(path)
    assert str(err.value) == (
        f"{path}: observers.momentum.momentum.gain[0]: "
        "Input should be a finite number (got '1e999')"
    )


def test_thresholds_and_column_map_refuse_non_finite(tmp_path: Path) -> None:
    shipped = read_thresholds(CONFIGS / "ur10e" / "thresholds.yaml").model_dump(mode="python")
    # every number the monitor uses; ``provenance`` is a free-form record of how the file
    # was made (tune's grids and measured sensitivity: a rate or delay may legitimately be
    # missing), read by people, never by the monitor
    leaves = [leaf for leaf in _float_leaves(shipped) if not str(leaf[0]).startswith("provenance")]
    assert len(leaves) > 50
    for path, (container, key) in leaves:
        good = container[key]
        container[key] = math.inf
        with pytest.raises(ValidationError) as err:
            ThresholdsFile.model_validate(shipped)
        container[key] = good
        assert _leaf_name(path) in format_validation_error("t.yaml", err.value), path
    bad = tmp_path / "thresholds.yaml"
    text = (CONFIGS / "ur10e" / "thresholds.yaml").read_text()
    bad.write_text(text.replace("margin: ", "margin: .inf #", 1))
    with pytest.raises(ConfigError, match=r"thresholds\.yaml: margin: .*finite.*\(got inf\)"):
        read_thresholds(bad)
    cmap = tmp_path / "columns.yaml"
    text = (CONFIGS / "ur10e" / "columns_31.yaml").read_text()
    cmap.write_text(text.replace("max_time_step: 1.0", "max_time_step: .nan"))
    with pytest.raises(ConfigError, match=r"columns\.yaml: max_time_step: .*\(got nan\)"):
        load_column_map(cmap)
