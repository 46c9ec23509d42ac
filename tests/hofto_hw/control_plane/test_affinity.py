"""The control plane, its planner and the stop server off the loop's CPU: with ``loop.cpus``
pinning the loop of a real service to one CPU of a machine with more, the control-plane
process, the planner it forks for a move and the stop socket's process run on the others
(hofto_hw.runtime.realtime.cpus_beside_loop); unpinned (or pinned to every CPU) they keep the
inherited affinity."""

from __future__ import annotations

import multiprocessing as mp
import os
from pathlib import Path

import numpy as np
import pytest
import yaml
from support.control_service import Service, children, move_if_still, socket_config, wait_for

from hofto_hw.client import Robot
from hofto_hw.runtime.realtime import cpus_beside_loop

ALL = sorted(os.sched_getaffinity(0))


def _beside(cpus: list[int] | None, out) -> None:
    if cpus is not None:
        os.sched_setaffinity(0, cpus)
    out.put(cpus_beside_loop())


def _in_child(cpus: list[int] | None) -> list[int] | None:
    ctx = mp.get_context("fork")
    q = ctx.Queue()
    p = ctx.Process(target=_beside, args=(cpus, q))
    p.start()
    got = q.get(timeout=30)
    p.join()
    return got


@pytest.mark.skipif(len(ALL) < 2 or len(ALL) != os.cpu_count(), reason="needs 2+ CPUs, all ours")
def test_cpus_beside_a_pinned_loop_are_the_others() -> None:
    assert _in_child([ALL[-1]]) == ALL[:-1]
    assert _in_child(None) is None  # not pinned: nothing to keep off
    assert _in_child(ALL) is None  # pinned to every CPU: nothing left beside it


@pytest.mark.skipif(len(ALL) < 2 or len(ALL) != os.cpu_count(), reason="needs 2+ CPUs, all ours")
def test_a_pinned_loop_s_control_plane_and_planner_run_on_the_other_cpus(tmp_path: Path) -> None:
    path = socket_config(tmp_path)
    data = yaml.safe_load(path.read_text())
    loop_cpu = ALL[-1]
    data["loop"]["cpus"] = [loop_cpu]
    path.write_text(yaml.safe_dump(data))
    svc = Service(tmp_path, "--hold", "--no-collision", config=path, log=False)
    try:
        with Robot.connect(socket=svc.sock) as robot:
            # answering: the control plane has its arguments and has set its affinity
            wait_for(lambda: robot.state().mode == "hold", "hold")
            assert os.sched_getaffinity(svc.proc.pid) == {loop_cpu}  # the loop's process
            (cp,) = [pid for pid, cmd in children(svc.proc.pid) if "hofto-hw-ctrl" in cmd]
            assert os.sched_getaffinity(cp) == set(ALL) - {loop_cpu}
            (stop,) = [pid for pid, cmd in children(svc.proc.pid) if "stop_server" in cmd]
            assert os.sched_getaffinity(stop) == set(ALL) - {loop_cpu}  # the stop socket's
            q0 = robot.state().q_cmd
            m = wait_for(
                lambda: move_if_still(robot, q0 + 0.1, speed=0.1, acceleration=0.1),
                "the move accepted",
            )
            planners = [pid for pid, _ in children(cp)]  # forked per plan, gone when sent
            for pid in planners:
                try:
                    assert os.sched_getaffinity(pid) == set(ALL) - {loop_cpu}
                except ProcessLookupError:
                    pass
            assert m.wait(timeout=120.0) == "completed"
            np.testing.assert_allclose(robot.state().q_cmd, q0 + 0.1, atol=1e-6)
    finally:
        svc.stop()
