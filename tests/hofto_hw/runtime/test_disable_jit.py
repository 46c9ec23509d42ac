"""numba's own switch, NUMBA_DISABLE_JIT=1, runs the compiled path's source as Python: the
same kernels (observers, model, control, safety, the fused call) and the native dynamics
through ctypes, never the numpy reference. ``hofto-hw run`` reports the same path, and a short
run's estimates and events agree with the compiled run's."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from hofto_hw.replay.flight_log import read_flight_log

pytestmark = pytest.mark.slow

#: past the scripted contact (3.0 s) and its detection: the estimates carry a collision
DURATION = "3.1"


def _run(folder: Path, disable_jit: bool) -> tuple[dict, Path, str]:
    env = {k: v for k, v in os.environ.items() if not k.startswith(("HOFTO_HW_NO_", "NUMBA_D"))}
    if disable_jit:
        env["NUMBA_DISABLE_JIT"] = "1"
    folder.mkdir()
    argv = ["run", "--clock", "sim", "--duration", DURATION]
    argv += ["--log-dir", str(folder), "--summary-json", str(folder / "s.json")]
    res = subprocess.run(
        [
            sys.executable,
            "-c",
            f"import sys; from hofto_hw.cli import main; sys.exit(main({argv!r}))",
        ],
        env=env,
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert res.returncode == 0, res.stderr[-3000:]
    (log,) = folder.glob("*.mcap")
    return json.loads((folder / "s.json").read_text()), log, res.stdout + res.stderr


def test_disabled_jit_runs_the_compiled_path_as_python(tmp_path: Path) -> None:
    ref, ref_log, _ = _run(tmp_path / "jit", disable_jit=False)
    got, got_log, text = _run(tmp_path / "python", disable_jit=True)
    acc = got["acceleration"]
    assert ref["acceleration"]["jit"] is True and acc["jit"] is False
    same = ("compiled", "kernels", "native", "fused", "why")
    assert {k: acc.get(k) for k in same} == {k: ref["acceleration"].get(k) for k in same}
    assert acc["compiled"] and acc["kernels"] == "numba" and acc["native"], acc
    assert "the compiled path as Python (NUMBA_DISABLE_JIT" in text
    assert "its kernels as Python" not in text  # no part fell back to its interpreter path

    a, b = read_flight_log(ref_log), read_flight_log(got_log)
    assert a.n_ticks == b.n_ticks == 3100
    for name in a.observers:
        peak = float(np.abs(a.tau_ext[name]).max())
        assert peak > 5.0  # the contact (20 N·m on joint 2) is in the window
        np.testing.assert_allclose(b.tau_ext[name], a.tau_ext[name], rtol=0, atol=1e-9 * peak)
    np.testing.assert_allclose(b.q, a.q, rtol=0, atol=1e-12)
    events = [(e.tick, e.kind_name, e.joint) for e in a.events]
    assert events == [(e.tick, e.kind_name, e.joint) for e in b.events]
    assert "collision" in [kind for _, kind, _ in events]
