"""Root-test plumbing shared by every test that needs veth pairs, network namespaces or raw
sockets: the skip/fail rule, unique names, the veth pair and the private namespace, an
emulator child process (``hofto-hw sim-ethercat`` / ``sim-canopen``) with its control
socket, and a ``hofto-hw run`` child process with its control socket and summary.

The rule: unprivileged, these tests skip with the reason; with env CI set they fail instead
(CI must run them). Names carry random hex and a per-process counter (:func:`unique_tag`),
since other sessions run such tests at the same time. Every wait is for a state (a ready
file, a line, a status), bounded by a generous timeout, never a sleep for a fixed time.

One rig at a time per machine (:func:`rig_slot`, held by :func:`emulator`): a rig is a
SCHED_FIFO loop (priority 50) and a SCHED_FIFO emulator (40) that must both keep their
rate for the scenario to mean anything. On the shared 2-core machine several sessions ran
such rigs at once (besides CI's): FIFO tasks of equal priority do not preempt each other,
and loops and emulators were held off their CPU for ~100 ms (measured in the flight logs:
wake-up 100.3 ms late; the CANopen emulator's arm, stepped per SYNC, froze meanwhile, so
the observers integrated 105 ms over one plant step: a false collision in free motion; a
following error at the demo path's 3.4 rad/s). The slot is an exclusive lock on
:data:`RIG_LOCK` (every session on the machine, any worktree): waiting for it is waiting
for the machine's real-time capacity, a state.
"""

from __future__ import annotations

import itertools
import json
import os
import secrets
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest

ROOT = Path(__file__).resolve().parents[2]
ER3A = ROOT / "configs" / "er3a.yaml"
_counter = itertools.count()
#: the machine-wide rig slot (see the module docstring); HOFTO_HW_RIG_LOCK overrides it
RIG_LOCK = Path(os.environ.get("HOFTO_HW_RIG_LOCK", "/tmp/hofto-hw-rt-rig.lock"))
RIG_WAIT = 1800.0  # [s] a whole rig test file of another session may run first
_rig_depth = 0


def require_root(need: str = "veth pairs and raw sockets") -> None:
    """Skip when not root; under CI (env CI set) fail instead, naming what needs root."""
    if os.geteuid() == 0:
        return
    if os.environ.get("CI"):
        pytest.fail(f"CI is set but the tests do not run as root: {need} need root")
    pytest.skip(f"needs root for {need} (set CI to make this a failure)")


def unique_tag() -> str:
    """Six random hex digits + a counter: the names live in the machine's network namespace,
    which other sessions share (their pids, from another pid namespace, can equal ours)."""
    return f"{secrets.token_hex(3)}{next(_counter) % 100}"


def wait_for(
    cond: Callable[[], bool], timeout: float, what: str, proc: subprocess.Popen | None = None
) -> None:
    """Wait until ``cond()``; AssertionError naming ``what`` after ``timeout`` [s] or when
    ``proc`` exits first."""
    deadline = time.monotonic() + timeout
    while not cond():
        if proc is not None and proc.poll() is not None:
            raise AssertionError(f"{what}: process exited with {proc.returncode}")
        if time.monotonic() > deadline:
            raise AssertionError(f"{what}: not reached within {timeout:.0f} s")
        time.sleep(0.02)


def stop_process(proc: subprocess.Popen | None, timeout: float = 30.0) -> None:
    """SIGTERM, wait, SIGKILL if it does not end (no error when already gone)."""
    if proc is None or proc.poll() is not None:
        return
    proc.send_signal(signal.SIGTERM)
    try:
        proc.wait(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()


@contextmanager
def veth_pair(master_prefix: str = "hm", slave_prefix: str = "hs") -> Iterator[tuple[str, str]]:
    """A veth pair named uniquely (``<prefix>`` + :func:`unique_tag`), deleted afterwards;
    needs root."""
    require_root()
    from drivers.sim.esc import veth

    tag = unique_tag()
    master, slave = f"{master_prefix}{tag}"[:15], f"{slave_prefix}{tag}"[:15]
    veth.create_pair(master, slave)
    try:
        yield master, slave
    finally:
        veth.delete_pair(master)


def _ip(*args: str) -> None:
    subprocess.run(["ip", *args], check=True, capture_output=True)


@contextmanager
def private_netns(prefix: str = "hns") -> Iterator[str]:
    """A network namespace with loopback up and multicast routed to it (python-can
    ``udp_multicast`` stays inside), deleted afterwards; needs root."""
    require_root("a private network namespace")
    name = f"{prefix}{unique_tag()}"
    _ip("netns", "add", name)
    try:
        _ip("netns", "exec", name, "ip", "link", "set", "lo", "up")
        _ip("netns", "exec", name, "ip", "route", "add", "224.0.0.0/4", "dev", "lo")
        yield name
    finally:
        subprocess.run(["ip", "netns", "del", name], capture_output=True)


def python_argv(netns: str | None) -> list[str]:
    """The interpreter, inside ``netns`` when given (``ip netns exec`` execs: same pid)."""
    return ["ip", "netns", "exec", netns, sys.executable] if netns else [sys.executable]


def child_env() -> dict[str, str]:
    """Environment for a child that imports the project and tests/support."""
    return dict(os.environ, PYTHONPATH=f"{ROOT}:{ROOT / 'tests'}")


@dataclass
class Emulator:
    """A running emulator process: its control socket and log."""

    proc: subprocess.Popen
    control: str
    log: Path

    def call(self, **request: object) -> dict:
        """One control request; RuntimeError with the emulator's message when refused."""
        from drivers.sim.esc.network import ControlClient

        return ControlClient(self.control).call(**request)


def er3a_run(*keys: str) -> dict[str, Any]:
    """These keys of configs/er3a.yaml's ``run:`` section (e.g. the simulated arm's
    ``model_error``, the demo ``path``), for a config that has none of its own."""
    import yaml

    run = yaml.safe_load(ER3A.read_text())["run"]
    return {k: run[k] for k in keys}


def run_config(
    folder: Path,
    name: str,
    *,
    base: Path = ER3A,
    overrun_streak: int,
    lost_cycles: int,
    bus: dict[str, Any] | None = None,
    ethercat: dict[str, Any] | None = None,
    run: dict[str, Any] | None = None,
    edit: Callable[[dict[str, Any]], None] | None = None,
) -> tuple[Path, dict[str, Any]]:
    """A copy of ``base`` for a ``hofto-hw run --clock real`` child, written to
    ``folder/name``; returns its path and data.

    The URDF path made absolute; ``bus`` keys set in ``bus:`` and ``ethercat`` merged into
    ``bus.ethercat``; ``safety.overrun_streak`` and ``safety.bus.lost_cycles`` as given (the
    host stalls and late frames of a loaded CI machine are not what these tests test);
    ``run``: None keeps the ``run:`` section with ``clock: real``, else it becomes
    ``{"clock": "real", **run}``; ``edit(data)`` for anything else.
    """
    import yaml

    from hofto_hw.config.loader import dump_yaml

    data = yaml.safe_load(base.read_text())
    data["robot"]["urdf"] = str((base.parent / data["robot"]["urdf"]).resolve())
    data["bus"].update(bus or {})
    if ethercat is not None:
        data["bus"]["ethercat"] = {**(data["bus"].get("ethercat") or {}), **ethercat}
    data["safety"]["overrun_streak"] = overrun_streak
    data["safety"]["bus"]["lost_cycles"] = lost_cycles
    if run is None:
        data["run"]["clock"] = "real"
    else:
        data["run"] = {"clock": "real", **run}
    if edit is not None:
        edit(data)
    path = folder / name
    path.write_text(dump_yaml(data))
    return path, data


def ethercat_run_config(
    folder: Path,
    master: str,
    name: str,
    *,
    overrun_streak: int,
    lost_cycles: int,
    ethercat: dict[str, Any] | None = None,
    run: dict[str, Any] | None = None,
    edit: Callable[[dict[str, Any]], None] | None = None,
    base: Path = ER3A,
) -> tuple[Path, dict[str, Any]]:
    """:func:`run_config` of ``base`` (configs/er3a.yaml) with the bus on ``master``, the
    master end of a veth pair, and the emulated slaves' SM watchdog at 2 s (their 100 ms one
    would take a drive out of OP after a host stall) updated with ``ethercat``."""
    return run_config(
        folder,
        name,
        base=base,
        overrun_streak=overrun_streak,
        lost_cycles=lost_cycles,
        bus={"transport": "ethercat", "interface": master},
        ethercat={"pdo_watchdog": 2.0, **(ethercat or {})},
        run=run,
        edit=edit,
    )


def sim_ethercat_args(iface: str, config: Path | str) -> list[str]:
    return ["sim-ethercat", "--iface", iface, "--config", str(config)]


def sim_canopen_args(interface: str, channel: str, config: Path | str) -> list[str]:
    return ["sim-canopen", "--interface", interface, "--channel", channel, "--config", str(config)]


@contextmanager
def rig_slot(what: str, timeout: float = RIG_WAIT) -> Iterator[None]:
    """Hold the machine's real-time rig slot (an exclusive ``flock`` on :data:`RIG_LOCK`)
    while ``what`` runs; re-entrant within a process. Waits for it (a state: the other
    session's rig ended), AssertionError naming the holder after ``timeout`` [s]."""
    import fcntl

    global _rig_depth
    if _rig_depth:
        _rig_depth += 1
        try:
            yield
        finally:
            _rig_depth -= 1
        return
    fd = os.open(RIG_LOCK, os.O_RDWR | os.O_CREAT, 0o666)
    try:

        def taken() -> bool:
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                return False
            return True

        try:
            wait_for(taken, timeout, f"the rig slot {RIG_LOCK} for {what}")
        except AssertionError as exc:
            holder = RIG_LOCK.read_text(errors="replace").strip()
            raise AssertionError(f"{exc}: held by {holder or 'an unnamed holder'}") from None
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"pid {os.getpid()}: {what} since {time.ctime()}\n".encode(), 0)
        _rig_depth = 1
        try:
            yield
        finally:
            _rig_depth = 0
            os.ftruncate(fd, 0)
            fcntl.flock(fd, fcntl.LOCK_UN)
    finally:
        os.close(fd)


@contextmanager
def emulator(
    command: Sequence[str],
    folder: Path,
    *,
    netns: str | None = None,
    timeout: float = 60.0,
    quiet_arm: bool = True,
) -> Iterator[Emulator]:
    """Start ``hofto-hw <command> --control ... --ready-file ...`` (sim-ethercat or
    sim-canopen, see :func:`sim_ethercat_args`), wait for its ready file, yield it; SIGTERM
    afterwards. A start-up failure raises AssertionError with the emulator's log. Holds the
    machine's rig slot (:func:`rig_slot`) from before the start to after the stop: the loop
    a test runs against it lives inside this context."""
    with rig_slot(" ".join(command[:1]) + f" in {folder.name}"):
        yield from _emulator(command, folder, netns=netns, timeout=timeout, quiet_arm=quiet_arm)


def _emulator(
    command: Sequence[str],
    folder: Path,
    *,
    netns: str | None,
    timeout: float,
    quiet_arm: bool,
) -> Iterator[Emulator]:
    control, ready = str(folder / "ctl.sock"), folder / "ready"
    log_path = folder / "emulator.log"
    cmd = [*python_argv(netns), "-m", "hofto_hw.cli", *command, "--control", control]
    cmd += ["--ready-file", str(ready)] + (["--quiet-arm"] if quiet_arm else [])
    with open(log_path, "w") as log:
        proc = subprocess.Popen(
            cmd, cwd=ROOT, env=child_env(), stdout=log, stderr=subprocess.STDOUT
        )
        try:
            try:
                wait_for(ready.exists, timeout, "emulator ready file", proc)
            except AssertionError as exc:
                log.flush()
                raise AssertionError(f"{exc}: {log_path.read_text()}") from None
            yield Emulator(proc, control, log_path)
        finally:
            stop_process(proc, 5.0)


@dataclass
class ServiceRun:
    """One ``hofto-hw run`` child process (optionally in ``netns``) with its control socket
    (``status``), stderr collected by a thread, and the summary it writes on exit."""

    folder: Path
    config: Path
    netns: str | None = None
    proc: subprocess.Popen | None = None
    socket: Path | None = None
    summary: Path | None = None
    log_dir: Path | None = None
    stderr: list[str] = field(default_factory=list)

    def start(self, *extra: str, log: bool = False, timeout: float = 120.0) -> None:
        """Start with ``--clock real --duration 3600`` (ended by :meth:`terminate`) and wait
        for its "running" line and control socket. ``log``: record an MCAP flight log into
        ``folder/logs`` (else ``--no-log``)."""
        self.socket = self.folder / "run.sock"
        self.summary = self.folder / "summary.json"
        cmd = [*python_argv(self.netns), "-m", "hofto_hw.cli", "run"]
        cmd += ["--config", str(self.config), "--clock", "real", "--duration", "3600"]
        cmd += ["--socket", str(self.socket), "--summary-json", str(self.summary)]
        if log:
            self.log_dir = self.folder / "logs"
            cmd += ["--log-dir", str(self.log_dir)]
        else:
            cmd += ["--no-log"]
        cmd += list(extra)
        self.proc = subprocess.Popen(
            cmd,
            cwd=ROOT,
            env=child_env(),
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        threading.Thread(target=self._read_stderr, daemon=True).start()
        wait_for(lambda: any("running" in s for s in self.stderr), timeout, "'running'", self.proc)
        wait_for(self.socket.exists, 30, "the run's control socket", self.proc)

    def _read_stderr(self) -> None:
        assert self.proc is not None and self.proc.stderr is not None
        for line in self.proc.stderr:
            self.stderr.append(line)

    def request(self, line: str, timeout: float = 30.0) -> dict[str, Any]:
        from hofto_hw.runtime.control_client import request

        assert self.socket is not None
        return request(self.socket, line, timeout=timeout)

    def status(self) -> dict[str, Any]:
        return self.request("status")

    def wait_state(self, state: str, timeout: float = 120.0) -> dict[str, Any]:
        """Wait until ``status`` reports ``state`` (e.g. "running"); returns that status."""
        last: dict[str, Any] = {}

        def reached() -> bool:
            last.clear()
            last.update(self.status())
            return last["state"] == state

        try:
            wait_for(reached, timeout, f"run state {state!r}", self.proc)
        except AssertionError as exc:
            raise AssertionError(f"{exc}; last status {last}; {''.join(self.stderr)}") from None
        return dict(last)

    def latched(self, kind: str) -> bool:
        return kind in self.status()["faults"]

    def wait_latched(self, kind: str, timeout: float = 60.0) -> None:
        try:
            wait_for(lambda: self.latched(kind), timeout, f"{kind} latched", self.proc)
        except AssertionError as exc:
            raise AssertionError(f"{exc}; {''.join(self.stderr)}") from None

    def wait_exit(self, timeout: float = 120.0) -> tuple[int, dict, str]:
        """Wait for the process to end; (exit code, summary, stdout)."""
        assert self.proc is not None and self.summary is not None
        try:
            out, _ = self.proc.communicate(timeout=timeout)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.communicate()
            raise AssertionError(f"run did not exit within {timeout:.0f} s") from None
        assert self.summary.exists(), "".join(self.stderr) + (out or "")
        return self.proc.returncode, json.loads(self.summary.read_text()), out or ""

    def terminate(self, timeout: float = 120.0) -> tuple[int, dict]:
        """SIGTERM; returns the exit code and the summary."""
        assert self.proc is not None
        self.proc.send_signal(signal.SIGTERM)
        code, summary, _ = self.wait_exit(timeout)
        return code, summary

    def log_files(self) -> list[Path]:
        """The MCAP files the run wrote (``start(log=True)``)."""
        return sorted(self.log_dir.glob("*.mcap")) if self.log_dir else []

    def close(self) -> None:
        stop_process(self.proc)


def first_event(summary: dict, kind: str) -> dict:
    """The first summary event of ``kind`` (AssertionError listing the kinds when none)."""
    events = [e for e in summary["events"] if e["kind"] == kind]
    assert events, f"no {kind} event in {[e['kind'] for e in summary['events']]}"
    return events[0]
