"""Contact episodes from per-sample detections."""

from __future__ import annotations

import numpy as np

from hofto_hw.replay.episodes import find_episodes


def test_episodes_merge_and_report_joints_and_peaks() -> None:
    t = np.arange(100) * 0.01
    joints = np.zeros((100, 3), dtype=bool)
    joints[10:20, 0] = True
    joints[22:25, 2] = True  # 0.03 s later: same contact
    joints[70:80, 1] = True  # a second contact
    tau = np.zeros((100, 3))
    tau[15, 0] = -12.0
    tau[23, 2] = 4.0
    tau[75, 1] = 30.0
    thr = np.full((100, 3), 10.0)
    eps = find_episodes(t, joints, tau, thr, rows=np.arange(101, 201), merge_gap=0.1)
    assert len(eps) == 2
    a, b = eps
    assert (a.start, a.end) == (0.10, 0.24)
    assert a.rows == (111, 125)
    assert a.joints == [1, 3]
    assert a.peak == [12.0, 0.0, 4.0]
    assert b.joints == [2] and b.peak_ratio == 3.0
    assert a.as_dict()["duration"] == a.end - a.start


def test_no_detection_no_episode_and_gap_splits() -> None:
    t = np.arange(50) * 0.01
    joints = np.zeros((50, 2), dtype=bool)
    tau = np.zeros((50, 2))
    thr = np.ones((50, 2))
    assert find_episodes(t, joints, tau, thr) == []
    joints[5:10, 0] = True
    joints[30:35, 0] = True
    assert len(find_episodes(t, joints, tau, thr, merge_gap=0.5)) == 1
    assert len(find_episodes(t, joints, tau, thr, merge_gap=0.1)) == 2
