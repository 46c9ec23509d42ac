"""The one YAML reader (hofto_hw.config.loader.read_yaml) cannot be made to hang or to fill
memory, and refuses what YAML would accept silently: an alias bomb answers at once, a FIFO
or a device is refused without waiting on it, a huge file is refused before it is read,
duplicate keys are refused naming file, line and key, and no message repeats a whole input.

The hang cases run the CLI in a subprocess under a timeout and an address-space limit
(tests/support/cli.run_limited): on the old reader they hang or die of MemoryError.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

import pytest
from support.cli import one_line_error, run_limited

from hofto_hw.config.loader import load_config, read_yaml
from hofto_hw.errors import ConfigError, ModelError

ROOT = Path(__file__).resolve().parents[3]
ER3A = ROOT / "configs" / "er3a.yaml"


def alias_bomb(path: Path) -> Path:
    """~450 bytes of nested aliases that expand to 9**9 (387 million) strings."""
    lines = ['a0: &a0 ["lol","lol","lol","lol","lol","lol","lol","lol","lol"]']
    lines += [f"a{i}: &a{i} [{','.join([f'*a{i - 1}'] * 9)}]" for i in range(1, 9)]
    lines.append("robot: *a8")
    path.write_text("\n".join(lines) + "\n")
    assert path.stat().st_size < 500
    return path


def test_alias_bomb_answers_in_under_a_second(tmp_path: Path) -> None:
    bomb = alias_bomb(tmp_path / "bomb.yaml")
    t0 = time.perf_counter()
    with pytest.raises(ConfigError) as err:
        load_config(bomb)
    assert time.perf_counter() - t0 < 1.0
    assert str(err.value) == (
        f"{bomb}: line 2: alias *a0 refused: aliases are not accepted in hofto-hw files "
        "(write the value out)"
    )


def test_alias_bomb_through_config_check_under_a_memory_limit(tmp_path: Path) -> None:
    bomb = alias_bomb(tmp_path / "bomb.yaml")
    code, out, err, _ = run_limited(["config", "check", str(bomb)], timeout=60, memory=1 << 30)
    assert code is not None, f"config check hung on an alias bomb: {err[-300:]}"
    one_line_error(code, err, str(bomb), "alias *a0 refused")


@pytest.mark.parametrize("kind", ["fifo", "/dev/zero", "100 MB file"])
def test_no_file_blocks_or_fills_memory(kind: str, tmp_path: Path) -> None:
    if kind == "fifo":
        path = tmp_path / "config.yaml"
        os.mkfifo(path)  # nobody ever writes: a blocking open or read waits forever
        words = "is a FIFO (named pipe), not a config file"
    elif kind == "/dev/zero":
        path = Path("/dev/zero")
        words = "is a character device, not a config file"
    else:
        path = tmp_path / "big.yaml"
        with path.open("wb") as f:  # sparse: no disk used
            f.truncate(100_000_000)
        words = "100000000 bytes; a config file is at most"
    code, out, err, _ = run_limited(["config", "check", str(path)], timeout=60, memory=1 << 30)
    assert code is not None, f"config check hung on a {kind}"
    one_line_error(code, err, f"{path}: {words}")


def test_duplicate_rate_is_refused_naming_file_line_and_key(tmp_path: Path) -> None:
    text = ER3A.read_text()
    assert "  rate_hz: 1000.0" in text
    bad = tmp_path / "er3a.yaml"
    bad.write_text(text.replace("  rate_hz: 1000.0", "  rate_hz: 1000.0\n  rate_hz: 250.0", 1))
    first = text[: text.index("  rate_hz: 1000.0")].count("\n") + 1
    with pytest.raises(ConfigError) as err:
        load_config(bad)
    assert str(err.value).startswith(
        f"{bad}: line {first + 1}: duplicate key 'rate_hz' (first at line {first})"
    )


def test_duplicate_key_in_a_flow_mapping_on_one_line(tmp_path: Path) -> None:
    path = tmp_path / "m.yaml"
    path.write_text("a: {x: 1, x: 2}\n")
    with pytest.raises(ModelError, match=r"m.yaml: line 1: duplicate key 'x' \(first at line 1\)"):
        read_yaml(path, "parameters file", ModelError)


def test_error_messages_quote_a_bounded_excerpt(tmp_path: Path) -> None:
    # a megabyte string where a number belongs, and an integer longer than int() parses
    text = ER3A.read_text()
    long_value = tmp_path / "long.yaml"
    long_value.write_text(text.replace("rate_hz: 1000.0", "rate_hz: " + "x" * 1_000_000, 1))
    long_int = tmp_path / "int.yaml"
    long_int.write_text(text.replace("rate_hz: 1000.0", "rate_hz: " + "9" * 10_000, 1))
    for path in (long_value, long_int):
        with pytest.raises(ConfigError) as err:
            load_config(path)
        message = str(err.value)
        assert message.startswith(f"{path}: ") and len(message) < 400, message[:500]
        assert "\n" not in message


def test_the_good_files_still_load() -> None:
    # aliases and duplicates are refused; everything shipped has neither
    for path in sorted((ROOT / "configs").rglob("*.yaml")):
        read_yaml(path, "file")


@pytest.mark.parametrize(
    ("argv", "what"),
    [
        (["log", "info", "FIFO"], "not a flight log (MCAP)"),
        (["log", "recover", "FIFO"], "not a flight log (MCAP)"),
        (["replay", str(ROOT / "configs" / "ur10e" / "parameters.yaml"), "FIFO"], "CSV recording"),
    ],
    ids=["log info", "log recover", "replay csv"],
)
def test_streamed_inputs_refuse_a_fifo_before_opening_it(argv, what, tmp_path: Path) -> None:
    fifo = tmp_path / ("run.mcap" if argv[0] == "log" else "rec.csv")
    os.mkfifo(fifo)
    argv = [str(fifo) if a == "FIFO" else a for a in argv]
    code, out, err, _ = run_limited(argv, timeout=60, memory=1 << 30)
    assert code is not None, f"{argv[:2]} blocked on a FIFO"
    one_line_error(code, err, f"{fifo}: is a FIFO (named pipe)", what)
