"""The commands run the compiled observers when they can and say once when they cannot."""

from __future__ import annotations

from hofto_hw import jit
from hofto_hw.commands import backend


def test_the_python_fallback_is_said_once_on_stderr(monkeypatch, capsys):
    monkeypatch.setattr(jit, "_DISABLED", True)
    monkeypatch.setattr(backend, "_said", False)
    assert backend.observer_backend() == "auto"
    assert backend.observer_backend() == "auto"
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert "kernels as Python" in err and "HOFTO_HW_NO_NUMBA" in err


def test_nothing_is_said_when_the_compiled_kernels_run(monkeypatch, capsys):
    monkeypatch.setattr(backend, "_said", False)
    if not jit.available():
        monkeypatch.setattr(jit, "_DISABLED", False)
        monkeypatch.setattr(jit, "_FAILED", "")
    backend.observer_backend()
    assert capsys.readouterr().err == ""
