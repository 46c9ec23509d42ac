"""Start-up progress lines: silent when the start-up is quick, each phase and the total once
it has taken long."""

from __future__ import annotations

import io

import pytest
from support.rootnet import wait_for

from hofto_hw.errors import UserError
from hofto_hw.runtime.startup import StartupProgress, progress_after


def test_a_quick_start_up_prints_nothing() -> None:
    out = io.StringIO()
    p = StartupProgress(after=600.0, stream=out)
    p.phase("loading the compiled kernels")
    p.phase("enabling the drives")
    p.done()
    assert out.getvalue() == ""


def test_a_slow_start_up_prints_each_phase_and_the_total() -> None:
    out = io.StringIO()
    p = StartupProgress("hofto-hw run", after=0.0, stream=out)
    p.phase("loading the compiled kernels")
    wait_for(lambda: "kernels" in out.getvalue(), 30, "the first progress line")
    p.phase("enabling the drives")
    p.phase("enabling the drives")  # said once
    took = p.done()
    lines = out.getvalue().splitlines()
    assert lines[0].startswith("hofto-hw run: starting: loading the compiled kernels (")
    assert lines[1].startswith("hofto-hw run: starting: enabling the drives (")
    assert lines[2] == f"hofto-hw run: started in {took:.1f} s"
    assert len(lines) == 3


def test_progress_after_comes_from_the_environment(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("HOFTO_HW_PROGRESS_AFTER", "0")
    assert StartupProgress(stream=io.StringIO()).after == 0.0
    monkeypatch.delenv("HOFTO_HW_PROGRESS_AFTER")
    assert progress_after() == 1.5
    for bad in ("soon", "-1", "nan", "inf"):
        monkeypatch.setenv("HOFTO_HW_PROGRESS_AFTER", bad)
        with pytest.raises(UserError, match=f"HOFTO_HW_PROGRESS_AFTER: .*got '{bad}'"):
            progress_after()
