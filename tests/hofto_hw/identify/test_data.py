"""Tests of hofto_hw.identify.data: CSV/MCAP input, bad rows, conditioning."""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import pytest

from hofto_hw.errors import ConfigError, UserError
from hofto_hw.identify.data import (
    Recording,
    condition,
    decimate,
    differentiate,
    load_column_map,
    load_csv,
    load_recording,
    lowpass,
    trim_standstill,
)

ROOT = Path(__file__).resolve().parents[3]
MAP31 = ROOT / "configs" / "ur10e" / "columns_31.yaml"
MAP25 = ROOT / "configs" / "ur10e" / "columns_25.yaml"
SAMPLE = ROOT / "tests" / "data" / "ur10e" / "excitation_30sec_12harm_rows601-840.csv"
SHARED = ROOT.parent / "shared" / "data" / "ur10e"
GAINS = np.array([10.0, 10.6956, 8.4566, 9.0029, 9.4800, 10.1232])


def _lines() -> list[str]:
    return SAMPLE.read_text().splitlines()


def _write(tmp_path: Path, lines: list[str], name: str = "rec.csv") -> Path:
    p = tmp_path / name
    p.write_text("\n".join(lines) + "\n")
    return p


def test_31_columns_in_si_units() -> None:
    raw = np.loadtxt(SAMPLE, delimiter=",")
    rec = load_csv(SAMPLE, MAP31)
    assert rec.n_samples == raw.shape[0] == 240
    assert rec.n_joints == 6
    np.testing.assert_array_equal(rec.t, raw[:, 0])
    np.testing.assert_array_equal(rec.q, raw[:, 1:7])
    np.testing.assert_array_equal(rec.qd, raw[:, 7:13])
    np.testing.assert_allclose(rec.tau, raw[:, 13:19] * GAINS)
    np.testing.assert_array_equal(rec.extra["torque_setpoint"], raw[:, 25:31])
    assert rec.rows[0] == 1 and rec.rows[-1] == 240
    assert rec.notes == []


def test_25_column_layout_reads_the_same_joint_data(tmp_path: Path) -> None:
    lines25 = [",".join(ln.split(",")[:25]) for ln in _lines()]
    p = _write(tmp_path, lines25)
    rec25 = load_csv(p, MAP25)
    rec31 = load_csv(SAMPLE, MAP31)
    np.testing.assert_array_equal(rec25.tau, rec31.tau)
    np.testing.assert_array_equal(rec25.qd, rec31.qd)
    assert rec25.extra == {}


def test_wrong_column_count_names_file_and_counts(tmp_path: Path) -> None:
    p = _write(tmp_path, [",".join(ln.split(",")[:25]) for ln in _lines()], "short.csv")
    with pytest.raises(UserError, match=r"short\.csv: rows have 25 columns.*expects 31"):
        load_csv(p, MAP31)


def test_nan_row_refused_with_row_and_column(tmp_path: Path) -> None:
    lines = _lines()
    f = lines[6].split(",")
    f[2] = "NaN"
    lines[6] = ",".join(f)
    p = _write(tmp_path, lines, "nan.csv")
    with pytest.raises(UserError, match=r"nan\.csv: row 7: column 3 \(q\): NaN"):
        load_csv(p, MAP31)


def test_nan_row_dropped_with_warning(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    lines = _lines()
    f = lines[6].split(",")
    f[9] = "nan"
    lines[6] = ",".join(f)
    p = _write(tmp_path, lines)
    with caplog.at_level(logging.WARNING):
        rec = load_csv(p, MAP31, bad_rows="drop")
    assert rec.n_samples == 239
    assert 7 not in rec.rows
    assert "dropped 1 bad rows (7)" in caplog.text
    assert rec.notes and "row 7" in rec.notes[0]


def test_non_monotonic_time_refused(tmp_path: Path) -> None:
    lines = _lines()
    lines[50], lines[51] = lines[51], lines[50]
    p = _write(tmp_path, lines, "back.csv")
    with pytest.raises(UserError, match=r"back\.csv: row 52: column time: .* does not advance"):
        load_csv(p, MAP31)


def test_time_restart_is_refused_even_when_dropping(tmp_path: Path) -> None:
    lines = _lines()
    p = _write(tmp_path, lines + lines, "twice.csv")
    with pytest.raises(UserError, match=r"twice\.csv: 240 of 480 rows are bad"):
        load_csv(p, MAP31, bad_rows="drop")


def test_truncated_last_row(tmp_path: Path) -> None:
    lines = _lines()
    lines[-1] = lines[-1][:60]
    p = _write(tmp_path, lines, "cut.csv")
    with pytest.raises(UserError, match=r"cut\.csv: row 240: \d+ columns, expected 31"):
        load_csv(p, MAP31)
    rec = load_csv(p, MAP31, bad_rows="drop")
    assert rec.rows[-1] == 239


def test_corrupt_rows_with_right_field_count(tmp_path: Path) -> None:
    # Like ur-20_02_19_15harm50secLoad.csv rows 2-10: 31 fields of garbage.
    lines = _lines()
    garbage = ["0.0000"] * 31
    garbage[0], garbage[4] = "-0.1231", "-1.125e+282"
    lines[1] = ",".join(garbage)
    jump = lines[2].split(",")
    jump[0] = "2.68e154"
    lines[2] = ",".join(jump)
    text = lines[3].split(",")
    text[15] = "1.2x"
    lines[3] = ",".join(text)
    p = _write(tmp_path, lines, "garbage.csv")
    with pytest.raises(UserError, match=r"row 2: column 5 \(q\).*exceeds.*3 bad rows in all: 2-4"):
        load_csv(p, MAP31)
    rec = load_csv(p, MAP31, bad_rows="drop")
    assert list(rec.rows[:2]) == [1, 5]


def test_too_short(tmp_path: Path) -> None:
    p = _write(tmp_path, _lines()[:5], "tiny.csv")
    with pytest.raises(UserError, match=r"tiny\.csv: too short: 5 rows"):
        load_csv(p, MAP31)


def test_row_range(tmp_path: Path) -> None:
    rec = load_csv(SAMPLE, MAP31, rows=(11, 100))
    assert rec.n_samples == 90 and rec.rows[0] == 11 and rec.rows[-1] == 100
    with pytest.raises(UserError, match="file ends at row 240"):
        load_csv(SAMPLE, MAP31, rows=(11, 400))


def test_missing_file_and_missing_map(tmp_path: Path) -> None:
    with pytest.raises(UserError, match=r"nope\.csv: recording not found"):
        load_csv(tmp_path / "nope.csv", MAP31)
    with pytest.raises(UserError, match="needs a column map"):
        load_recording(SAMPLE)


def test_bad_column_map_names_field(tmp_path: Path) -> None:
    p = tmp_path / "map.yaml"
    p.write_text("time: 1\nq: [2, 3]\nqd: [4, 5]\ncurrent: [6, 7]\n")
    with pytest.raises(ConfigError, match=r"map\.yaml: .*current_to_torque needs 2 gains"):
        load_column_map(p)
    p.write_text("time: 1\nq: [2]\nqd: [3]\ntorque: [4]\nbogus: 1\n")
    with pytest.raises(ConfigError, match=r"map\.yaml: bogus"):
        load_column_map(p)


def _synthetic(t: np.ndarray, n: int = 2) -> Recording:
    q = np.stack([np.sin(2.0 * t + j) for j in range(n)], axis=1)
    qd = np.stack([2.0 * np.cos(2.0 * t + j) for j in range(n)], axis=1)
    return Recording(
        t=t, q=q, qd=qd, tau=qd.copy(), source="synthetic", rows=np.arange(1, t.size + 1)
    )


def test_differentiate_uses_real_time_stamps() -> None:
    rng = np.random.default_rng(1)
    t = np.cumsum(rng.uniform(0.008, 0.016, 800))
    x = np.sin(2.0 * t)
    d = differentiate(x, t)
    assert np.max(np.abs(d[1:-1] - 2.0 * np.cos(2.0 * t[1:-1]))) < 2e-3
    # Pretending the spacing is uniform would be far off on this jittered grid:
    naive = np.gradient(x, np.median(np.diff(t)))
    assert np.max(np.abs(naive - 2.0 * np.cos(2.0 * t))) > 0.1


def test_lowpass_is_zero_phase_and_removes_noise() -> None:
    t = np.arange(0.0, 20.0, 0.01)
    slow = np.sin(2 * np.pi * 0.5 * t)
    fast = 0.5 * np.sin(2 * np.pi * 30.0 * t)
    y = lowpass(slow + fast, t, 5.0)
    inner = slice(100, -100)
    assert np.max(np.abs(y[inner] - slow[inner])) < 0.01


def test_trim_standstill_and_condition() -> None:
    t = np.arange(0.0, 10.0, 0.01)
    rec = _synthetic(t)
    still = (t < 2.0) | (t > 8.0)
    rec.qd[still] = 0.0
    trimmed = trim_standstill(rec, speed=0.01, margin=0.5)
    assert trimmed.t[0] == pytest.approx(1.5, abs=0.011)
    assert trimmed.t[-1] == pytest.approx(8.5, abs=0.011)
    moving = _synthetic(t)
    c = condition(moving, cutoff_hz=5.0, trim=False)
    assert c.qdd is not None
    inner = slice(100, -100)
    expect = -4.0 * np.sin(2.0 * t[:, None] + np.arange(2))
    assert np.max(np.abs(c.qdd[inner] - expect[inner])) < 0.02


def test_decimate_and_nyquist_check() -> None:
    t = np.arange(0.0, 10.0, 0.01)
    rec = _synthetic(t)
    assert decimate(rec, 4).n_samples == 250
    with pytest.raises(UserError, match="above the Nyquist rate"):
        condition(rec, cutoff_hz=20.0, trim=False, decimation=4)
    with pytest.raises(UserError, match="too short after decimation"):
        decimate(rec, 100)


@pytest.mark.data
@pytest.mark.skipif(not SHARED.is_dir(), reason="../shared/data/ur10e (UR10e recordings) absent")
def test_real_file_with_corrupt_and_truncated_rows() -> None:
    path = SHARED / "identification" / "ur-20_02_19_15harm50secLoad.csv"
    with pytest.raises(UserError, match=r"row 2: .*bad rows in all: 2-10, 6107"):
        load_csv(path, MAP31)
    rec = load_csv(path, MAP31, bad_rows="drop")
    assert rec.rows[0] == 1 and rec.rows[1] == 11
    assert rec.rows[-1] == 6106
    assert np.all(np.diff(rec.t) > 0)
