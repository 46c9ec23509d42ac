"""Round trip of joint-state MCAP logs and their use as recordings."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from hofto_hw.errors import UserError
from hofto_hw.identify.data import load_recording
from hofto_hw.recording import JointStateWriter, read_joint_states, write_joint_states


def _series(n_samples: int = 50, n: int = 6) -> tuple[np.ndarray, ...]:
    rng = np.random.default_rng(3)
    t = 100.0 + np.cumsum(rng.uniform(0.008, 0.012, n_samples))
    q, qd, tau = (rng.normal(size=(n_samples, n)) for _ in range(3))
    return t, q, qd, tau


def test_round_trip(tmp_path: Path) -> None:
    t, q, qd, tau = _series()
    p = write_joint_states(tmp_path / "log.mcap", t, q, qd, tau, [f"j{i}" for i in range(6)])
    js = read_joint_states(p)
    assert js.names == [f"j{i}" for i in range(6)]
    np.testing.assert_allclose(js.t, t, atol=1e-9)
    np.testing.assert_array_equal(js.q, q)
    np.testing.assert_array_equal(js.qd, qd)
    np.testing.assert_array_equal(js.tau, tau)


def test_log_loads_as_recording(tmp_path: Path) -> None:
    t, q, qd, tau = _series()
    p = write_joint_states(tmp_path / "log.mcap", t, q, qd, tau)
    rec = load_recording(p)
    assert rec.n_samples == 50 and rec.n_joints == 6
    np.testing.assert_array_equal(rec.tau, tau)
    assert rec.source == str(p)


def test_nan_in_log_is_refused(tmp_path: Path) -> None:
    t, q, qd, tau = _series()
    tau[7, 2] = np.nan
    p = write_joint_states(tmp_path / "nan.mcap", t, q, qd, tau)
    with pytest.raises(UserError, match=r"nan\.mcap: message 8: effort\[2\] is not finite"):
        load_recording(p)


def test_not_an_mcap_file(tmp_path: Path) -> None:
    p = tmp_path / "junk.mcap"
    p.write_bytes(b"this is not mcap at all")
    with pytest.raises(UserError, match=r"junk\.mcap: not a readable MCAP log"):
        read_joint_states(p)


def test_empty_log(tmp_path: Path) -> None:
    with JointStateWriter(tmp_path / "empty.mcap", ["a", "b"]):
        pass
    with pytest.raises(UserError, match="no sensor_msgs/msg/JointState messages"):
        read_joint_states(tmp_path / "empty.mcap")
