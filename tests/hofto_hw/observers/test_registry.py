"""One observer registry: the config union and the registry list the same observers."""

from __future__ import annotations

import typing

import numpy as np
import pytest

from hofto_hw.config.models import ObserverConfig, SystemConfig
from hofto_hw.observers import make_observer
from hofto_hw.observers.registry import OBSERVERS, replay_default


def _union_classes() -> set[type]:
    union = typing.get_args(ObserverConfig)[0]
    return set(typing.get_args(union))


def test_every_config_class_has_an_entry_and_vice_versa() -> None:
    union = _union_classes()
    registered = {e.config for e in OBSERVERS.values()}
    assert union == registered
    for name, entry in OBSERVERS.items():
        assert entry.config.model_fields["type"].default == name


@pytest.mark.parametrize("name", list(OBSERVERS))
def test_replay_default_builds_and_runs(er3a_model, name: str) -> None:
    cfg = replay_default(name, er3a_model.n)
    assert isinstance(cfg, OBSERVERS[name].config)
    obs = make_observer(cfg, er3a_model)
    q, qd = er3a_model.home, np.zeros(er3a_model.n)
    obs.reset(q, qd)
    assert obs.update(q, qd, np.zeros(er3a_model.n), 0.01).shape == (er3a_model.n,)


@pytest.mark.parametrize("name", [n for n in OBSERVERS if n != "direct"])
def test_per_joint_lengths_come_from_the_config_class(er3a_config, name: str) -> None:
    raw = er3a_config.model_dump(mode="json")
    cfg = replay_default(name, 5).model_dump(mode="json")  # one joint short
    raw["observers"] = {"x": cfg}
    with pytest.raises(ValueError, match=r"observers\.x\..* has 5 entries, expected 6"):
        SystemConfig.model_validate(raw)
