"""Numbers a user sets have upper bounds where one exists physically or by design, checked
at load (before any costly work), and the observer stability check costs a bounded number of
steps whatever the rate.

Before: ``loop.rate_hz: 1.0e9`` hung ``config check`` and ``run`` for more than 10 minutes
(the stability check stepped the observer 2·10⁹ times); a torque limit above what 0x6072
holds was clipped silently by the driver; a 10⁶ s transition timeout or a 10¹² s run was
accepted.
"""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml
from pydantic import ValidationError
from support.cli import one_line_error, run_limited

from hofto_hw.config.drives import BusConfig
from hofto_hw.config.loader import load_config
from hofto_hw.errors import ConfigError

ROOT = Path(__file__).resolve().parents[3]
ER3A = ROOT / "configs" / "er3a.yaml"
DRIVE = {
    "counts_per_rev": 131072,
    "gear_ratio": 100.0,
    "rated_torque": 640,
    "rated_current": 2800,
    "torque_constant": 0.23,
    "torque_limit": 120.0,
    "quick_stop_deceleration": 10.0,
}


def _variant(tmp_path: Path, edit) -> Path:
    data = yaml.safe_load(ER3A.read_text())
    edit(data)
    data["robot"]["urdf"] = str(ER3A.parent / data["robot"]["urdf"])
    path = tmp_path / "er3a.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def test_config_check_of_a_gigahertz_loop_answers_at_once(tmp_path: Path) -> None:
    path = _variant(tmp_path, lambda d: d["loop"].update(rate_hz=1.0e9))
    code, out, err, seconds = run_limited(["config", "check", str(path)], timeout=120)
    assert code is not None, "config check hung on loop.rate_hz: 1e9"
    one_line_error(code, err, str(path), "loop.rate_hz", "less than or equal to 10000")


def test_the_nonlinear_stability_check_is_bounded_whatever_the_rate(
    er3a_config, er3a_model, monkeypatch
) -> None:
    from hofto_hw.observers import hofto
    from hofto_hw.observers.stability import check_observer

    steps = [0]
    step = hofto.HoftoCore.step

    def counted(self, *args, **kwargs):
        steps[0] += 1
        assert steps[0] <= 100_000, "the stability check steps without bound"
        return step(self, *args, **kwargs)

    monkeypatch.setattr(hofto.HoftoCore, "step", counted)
    check_observer("hofto", er3a_config.observers["hofto"], er3a_model, 1.0e9)
    assert 0 < steps[0] <= 20_000


@pytest.mark.parametrize(
    ("edit", "field"),
    [
        (lambda d: d["run"].update(duration=1.0e12), "run.duration"),
        (lambda d: d["bus"].update(transition_timeout=1.0e6), "bus.transition_timeout"),
        (lambda d: d["service"].update(status_interval=1.0e9), "service.status_interval"),
        (
            lambda d: (
                d.setdefault("motion", {}).update(record_seconds=3600.0)
                or d["loop"].update(rate_hz=5000.0)
            ),
            "motion.record_seconds",
        ),
    ],
    ids=["run.duration", "transition_timeout", "status_interval", "record buffer"],
)
def test_unbounded_numbers_are_refused_at_load(edit, field: str, tmp_path: Path) -> None:
    path = _variant(tmp_path, lambda d: (d.setdefault("service", {}), edit(d)))
    with pytest.raises(ConfigError, match=field.replace(".", r"\.")):
        load_config(path)


@pytest.mark.parametrize(
    ("change", "words"),
    [
        ({"torque_limit": 5000.0}, "above what 0x6072"),
        ({"quick_stop_deceleration": 1.0e4}, "above what 0x6085"),
    ],
)
def test_drive_limits_must_fit_their_objects(change: dict, words: str) -> None:
    with pytest.raises(ValidationError, match=words):
        BusConfig(transport="sim", drives=[{**DRIVE, **change}])
    # the largest value that fits is accepted (65535 per mille of 0.64 N·m x 100)
    assert BusConfig(transport="sim", drives=[{**DRIVE, "torque_limit": 4194.0}])


def test_run_duration_option_is_bounded() -> None:
    argv = ["run", "--duration", "1e12", "--no-log", "--clock", "sim"]
    code, out, err, _ = run_limited(argv, timeout=120)
    assert code is not None, "a 1e12 s run was accepted and ran"
    one_line_error(code, err, "--duration", "at most 604800 s")


@pytest.mark.parametrize(
    ("argv", "words"),
    [
        (["demo", "--duration", "1e9"], "argument --duration: at most 3600 s"),
        (["excite", "--config", "er3a", "-o", "OUT", "--velocity-scale", "3"], "at most 1"),
        (["excite", "--config", "er3a", "-o", "OUT", "--harmonics", "100000"], "at most 50"),
        (
            ["excite", "--config", "er3a", "-o", "OUT", "--period", "600", "--cycles", "100"]
            + ["--rate", "1000"],
            "6e+07 samples; at most 1e+07",
        ),
    ],
    ids=["demo duration", "velocity scale", "harmonics", "excitation size"],
)
def test_command_numbers_with_a_bound_by_design(argv, words, tmp_path: Path) -> None:
    out = tmp_path / "x.csv"
    argv = [str(out) if a == "OUT" else a for a in argv]
    code, stdout, err, _ = run_limited(argv, timeout=120)
    assert code is not None, f"{argv[:3]} ran on"
    one_line_error(code, err, words)
    assert not out.exists()


@pytest.mark.parametrize(
    ("field", "value", "bound"),
    [
        ("ramp_s", 60.0, "less than or equal to 5"),
        ("ramp_s", -0.1, "greater than or equal to 0"),
        ("holding_fraction", 1.5, "less than or equal to 1"),
        ("holding_fraction", 0.0, "greater than 0"),
    ],
)
def test_the_payload_ramp_and_holding_fraction_are_bounded(
    tmp_path: Path, field: str, value: float, bound: str
) -> None:
    path = _variant(tmp_path, lambda d: d["robot"]["rated_payload"].update({field: value}))
    with pytest.raises(ConfigError) as exc:
        load_config(path)
    msg = str(exc.value)
    assert f"robot.rated_payload.{field}" in msg and bound in msg and "\n" not in msg, msg
    ok = _variant(tmp_path, lambda d: d["robot"]["rated_payload"].update(ramp_s=0.0))
    assert load_config(ok).robot.rated_payload.ramp_s == 0.0  # 0: one step
