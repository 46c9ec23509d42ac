"""Taught-path files (bad files -> one clear line), jerk-limited moves and time scaling."""

from __future__ import annotations

import numpy as np
import pytest

from hofto_hw.control.path_timing import (
    Limits,
    jerk_limited_move,
    replay_trajectory,
    time_scale_path,
)
from hofto_hw.control.taught_path import (
    TaughtPathRecorder,
    load_taught_path,
    save_taught_path,
)
from hofto_hw.errors import UserError

DT = 1e-3


def _limits(n: int = 6) -> Limits:
    return Limits(np.full(n, 1.0), np.full(n, 4.0), np.full(n, 40.0))


def _recorded(model, seconds: float = 3.0) -> TaughtPathRecorder:
    rec = TaughtPathRecorder(model.n, 10000)
    t = np.arange(0.0, seconds, DT)
    s = 0.5 * (1 - np.cos(np.pi * t / seconds))  # at rest at both ends
    for tk, sk in zip(t, s, strict=True):
        rec.push(10.0 + tk, model.home + sk * np.array([0.4, -0.2, 0.3, 0.5, -0.3, 0.8]))
    return rec


def test_round_trip(er3a_model, tmp_path) -> None:
    rec = _recorded(er3a_model)
    file = save_taught_path(rec.path(er3a_model), tmp_path / "p.csv")
    back = load_taught_path(file, er3a_model)
    assert back.t[0] == 0.0 and back.t.shape == (3000,)
    np.testing.assert_allclose(back.q, rec.q[: rec.count], atol=1e-9)


def test_recorder_keeps_the_start_when_full(er3a_model) -> None:
    rec = TaughtPathRecorder(6, 3)
    for k in range(5):
        rec.push(k, np.full(6, k))
    assert rec.count == 3 and rec.overflow and rec.q[2, 0] == 2


@pytest.mark.parametrize(
    ("content", "message"),
    [
        (b"", "empty file"),
        (b"\x89MCAP0\r\n\x00\x00\x01", "binary data"),
        (b"t,a,b\n0,1,2\n", "not a hofto-hw taught path"),
        (b"# hofto-hw taught path v1\n# robot: ur10e\nt\n", "taught on robot 'ur10e'"),
    ],
)
def test_bad_files(er3a_model, tmp_path, content, message) -> None:
    f = tmp_path / "bad.csv"
    f.write_bytes(content)
    with pytest.raises(UserError, match=message) as err:
        load_taught_path(f, er3a_model)
    assert "\n" not in str(err.value) and str(f) in str(err.value)


def test_truncated_non_monotonic_other_joints_outside_limits(er3a_model, tmp_path) -> None:
    rec = _recorded(er3a_model, 0.1)
    good = save_taught_path(rec.path(er3a_model), tmp_path / "p.csv").read_text()
    cut = tmp_path / "cut.csv"
    cut.write_text(good[: len(good) - 40])
    with pytest.raises(UserError, match=r"line \d+: \d values, expected 7 \(truncated"):
        load_taught_path(cut, er3a_model)
    lines = good.splitlines()
    lines[5], lines[6] = lines[6], lines[5]
    swapped = tmp_path / "swap.csv"
    swapped.write_text("\n".join(lines))
    with pytest.raises(UserError, match="time does not increase"):
        load_taught_path(swapped, er3a_model)
    other = tmp_path / "joints.csv"
    other.write_text(good.replace("joint_6", "wrist_3"))
    with pytest.raises(UserError, match="do not match"):
        load_taught_path(other, er3a_model)
    far = tmp_path / "far.csv"
    lines = good.splitlines()
    lines[4] = "0.0005," + ",".join(["9.0"] * 6)
    far.write_text("\n".join(lines))
    with pytest.raises(UserError, match="outside its limits"):
        load_taught_path(far, er3a_model)


def test_jerk_limited_move_respects_limits() -> None:
    lim = _limits()
    q0, q1 = np.zeros(6), np.array([0.5, -0.3, 0.2, 1.0, 0.0, -0.7])
    m = jerk_limited_move(q0, q1, lim, DT)
    np.testing.assert_allclose(m.q[-1], q1, atol=1e-9)
    np.testing.assert_allclose(m.qd[-1], 0.0, atol=1e-9)
    assert np.all(np.abs(m.qd) <= lim.velocity + 1e-9)
    assert np.all(np.abs(m.qdd) <= lim.acceleration + 1e-9)
    jerk = np.abs(np.diff(m.qdd, axis=0)) / DT
    assert np.all(jerk <= lim.jerk * (1 + 1e-6))


def test_time_scaled_path_within_limits_on_the_taught_geometry(er3a_model) -> None:
    rec = _recorded(er3a_model, 1.0)  # too fast for the limits: must be slowed down
    path = rec.path(er3a_model)
    lim = _limits()
    tr = time_scale_path(path.t, path.q, lim, DT)
    assert tr.scale > 1.0
    assert np.all(np.abs(tr.qd) <= lim.velocity * 1.001)
    assert np.all(np.abs(tr.qdd) <= lim.acceleration * 1.01)
    assert np.all(np.abs(np.diff(tr.qdd, axis=0)) / DT <= lim.jerk * 1.01)
    np.testing.assert_allclose(tr.q[0], path.q[0], atol=1e-9)
    np.testing.assert_allclose(tr.q[-1], path.q[-1], atol=1e-9)
    # geometry: every replayed point is near the taught polyline (joint space)
    d = np.min(np.linalg.norm(tr.q[:, None, ::] - path.q[None, :], axis=2), axis=1)
    assert d.max() < 2e-3


def test_replay_joins_move_and_path_without_jerk_jump(er3a_model) -> None:
    rec = _recorded(er3a_model, 2.0)
    path = rec.path(er3a_model)
    lim = _limits()
    tr = replay_trajectory(er3a_model.home - 0.2, path.t, path.q, lim, DT)
    assert tr.segments[1] > 0
    assert np.all(np.abs(np.diff(tr.qdd, axis=0)) / DT <= lim.jerk * 1.01)


def test_a_bad_line_is_named_by_the_checked_read(er3a_model, tmp_path) -> None:
    """The fast reader takes a whole good file; any bad line falls back to the line-by-line
    read, which names it (a word, a non-finite number, a blank line is skipped)."""
    good = save_taught_path(_recorded(er3a_model, 0.1).path(er3a_model), tmp_path / "p.csv")
    lines = good.read_text().splitlines()
    blank = tmp_path / "blank.csv"
    blank.write_text("\n".join([*lines[:6], "", *lines[6:]]) + "\n")
    np.testing.assert_array_equal(
        load_taught_path(blank, er3a_model).q, load_taught_path(good, er3a_model).q
    )
    for bad, message in (("abc", "line 6: not a number"), ("nan", "line 6: non-finite value")):
        f = tmp_path / f"{bad}.csv"
        f.write_text("\n".join([*lines[:5], lines[5].replace(lines[5].split(",")[2], bad, 1),
                                *lines[6:]]))  # fmt: skip
        with pytest.raises(UserError, match=message):
            load_taught_path(f, er3a_model)


def test_a_replay_plan_sampled_in_pieces_is_the_whole_trajectory(er3a_model) -> None:
    """replay_plan's rows, taken in chunks of any size (as the planner streams them), are
    bit for bit replay_trajectory's: the move to the start, then the scaled path."""
    from hofto_hw.control.path_timing import replay_plan

    path = _recorded(er3a_model).path(er3a_model)
    q_now = er3a_model.home + 0.1
    whole = replay_trajectory(q_now, path.t, path.q, _limits(), DT)
    plan = replay_plan(q_now, path.t, path.q, _limits(), DT)
    assert plan.n_rows == whole.q.shape[0] and plan.segments == whole.segments
    assert plan.segments[1] > 0 and plan.scale == whole.scale
    for size in (1, 256, 777, plan.n_rows):
        parts = [plan.rows(i, min(plan.n_rows, i + size)) for i in range(0, plan.n_rows, size)]
        for k, name in enumerate(("q", "qd", "qdd")):
            got = np.vstack([p[k] for p in parts])
            np.testing.assert_array_equal(got, getattr(whole, name))
