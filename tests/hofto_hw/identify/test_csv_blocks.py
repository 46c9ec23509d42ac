"""The CSV reader reads in blocks into preallocated arrays: the result must not depend on
where the blocks end, bad rows are still named, progress is reported."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import pytest

from hofto_hw.errors import UserError
from hofto_hw.identify import data
from hofto_hw.progress import Progress

ROOT = Path(__file__).resolve().parents[3]
COLUMNS = ROOT / "configs" / "ur10e" / "columns_31.yaml"
EXCITATION = ROOT / "tests" / "data" / "ur10e" / "excitation_30sec_12harm_rows601-840.csv"


def _same(a: data.Recording, b: data.Recording) -> None:
    for name in ("t", "q", "qd", "tau", "rows"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    assert a.extra.keys() == b.extra.keys()
    assert a.notes == b.notes


@pytest.mark.parametrize("chunk", [97, 1000, 4096])
def test_block_boundaries_do_not_change_the_result(chunk, tmp_path, monkeypatch) -> None:
    lines = EXCITATION.read_text().splitlines()
    f = lines[40].split(",")
    f[9] = "oops"  # a bad row in the middle of some block
    lines[40] = ",".join(f)
    p = tmp_path / "rec.csv"
    p.write_text("\r\n".join(lines) + "\r\n\r\n")  # CRLF and a trailing empty line
    whole = data.load_csv(p, COLUMNS, bad_rows="drop")
    monkeypatch.setattr(data, "CHUNK_BYTES", chunk)
    _same(data.load_csv(p, COLUMNS, bad_rows="drop"), whole)
    part = data.load_csv(p, COLUMNS, rows=(30, 200), bad_rows="drop")
    assert part.rows[0] == 30 and part.rows[-1] == 200 and 41 not in part.rows
    with pytest.raises(UserError, match=r"row 41: column 10: not a number \('oops'\)"):
        data.load_csv(p, COLUMNS)
    with pytest.raises(UserError, match="file ends at row 240"):
        data.load_csv(p, COLUMNS, rows=(1, 500))


def test_replay_reads_no_extra_columns_and_reports_progress(tmp_path) -> None:
    calls: list[tuple[int, int]] = []
    rec = data.load_csv(
        EXCITATION, COLUMNS, keep_extra=False, progress=lambda k, n: calls.append((k, n))
    )
    assert rec.extra == {} and rec.n_samples == 240
    assert calls and calls[-1] == (240, 240)
    full = data.load_csv(EXCITATION, COLUMNS)
    assert set(full.extra) == {"current_setpoint", "torque_setpoint"}
    np.testing.assert_array_equal(full.tau, rec.tau)


def test_progress_lines_only_for_long_work() -> None:
    out = io.StringIO()
    quiet = Progress("reading", 100, after=3600.0, stream=out)
    quiet.update(50)
    assert out.getvalue() == ""
    loud = Progress("reading", 200, after=0.0, every=0.0, stream=out)
    loud.update(50)
    loud.update(200)
    assert out.getvalue().splitlines() == ["reading: 50/200 (25 %)", "reading: 200/200 (100 %)"]
