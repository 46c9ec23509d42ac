"""Shared CLI pieces: the config resolver (path or robot name), defaults shown by --help."""

from __future__ import annotations

import argparse
from pathlib import Path

import pytest

from hofto_hw.cli import COMMANDS, build_parser, main
from hofto_hw.commands.args import HelpFormatter
from hofto_hw.config.locate import PROJECT_CONFIGS, find_config
from hofto_hw.errors import UserError

ROOT = Path(__file__).resolve().parents[3]
PARAMS = ROOT / "configs" / "ur10e" / "parameters.yaml"
PUSH = ROOT / "tests" / "data" / "ur10e" / "push_pose_1_rows100-600.csv"


def test_find_config_by_path_name_and_robot(tmp_path, monkeypatch) -> None:
    monkeypatch.chdir(tmp_path)  # robot names resolve from anywhere, not only the repo root
    assert find_config("ur10e") == PROJECT_CONFIGS / "ur10e.yaml"
    own = tmp_path / "mine.yaml"
    own.write_text("x")
    assert find_config(str(own)) == own
    assert find_config(None, "er3a", PROJECT_CONFIGS / "er3a") == PROJECT_CONFIGS / "er3a.yaml"
    with pytest.raises(UserError, match=r"'robot9' is neither a file nor a known robot.*ur10e"):
        find_config("robot9")
    with pytest.raises(UserError, match="config file not found"):
        find_config("nowhere/ur10e.yaml")
    with pytest.raises(UserError, match="is a folder"):
        find_config(str(tmp_path))
    with pytest.raises(UserError, match="unknown robot 'robot9'"):
        find_config(None, "robot9", tmp_path)


def test_config_by_robot_name_on_every_command(capsys, tmp_path) -> None:
    assert main(["replay", str(PARAMS), str(PUSH), "--config", "ur10e"]) == 0
    assert "contact episode(s)" in capsys.readouterr().out
    # identify and excite accept a name too: the name resolves, then the data is judged
    code = main(["identify", "--config", "ur10e", "-o", str(tmp_path / "p.yaml"), f"{PUSH}@1:5"])
    err = capsys.readouterr().err
    assert code == 2 and "too short" in err and "--config" not in err
    code = main(["replay", str(PARAMS), str(PUSH), "--config", "robot9"])
    assert code == 2 and "'robot9' is neither a file nor a known robot" in capsys.readouterr().err


def _subparsers(parser: argparse.ArgumentParser):
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield name, sub
                yield from ((f"{name} {n}", s) for n, s in _subparsers(sub))


def test_help_shows_every_default() -> None:
    parser = build_parser()
    seen = set()
    for name, sub in _subparsers(parser):
        seen.add(name.split()[0])
        actions = [
            a
            for a in sub._actions
            if a.option_strings
            and a.default not in (None, False, argparse.SUPPRESS)
            and not isinstance(a, argparse._HelpAction)
        ]
        if not actions:
            continue
        assert sub.formatter_class is HelpFormatter, name
        text = " ".join(sub.format_help().split())
        for a in actions:
            shown = HelpFormatter(name)._get_help_string(a) or ""
            assert "default" in shown, (name, a.option_strings)
            assert " ".join(shown.split()).replace("%(default)s", str(a.default))[:30] in text
    assert seen == set(COMMANDS)
