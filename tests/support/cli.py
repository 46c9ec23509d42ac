"""The CLI tests' check of a user error: exit code 2 and one line, never a traceback."""

from __future__ import annotations


def one_line_error(code: int, err: str, *needles: str) -> str:
    """Assert ``code`` is 2 and ``err`` is one line without a traceback that contains every
    one of ``needles``; returns that line."""
    assert code == 2, err
    assert "Traceback" not in err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    for needle in needles:
        assert needle in lines[0], (needle, err)
    return lines[0]
