"""SIGTERM (or SIGINT) during ``hofto-hw run``'s start-up is a clean stop at any phase: no drive
left enabled, the bus closed, the control plane's process and socket and the flight recorder's
writer gone, its log closed and readable; exit 0 for SIGTERM (128 + 2 for SIGINT).

The phases are hit exactly: the run is ``cli.main`` in a subprocess in which one start-up step
is wrapped so that it sends the signal to its own process at that step (before or after the
real step); the one test with an outside sender waits for the start-up's progress line of a
cold compile (an empty numba cache), not for a time. The helper processes (writer, control
plane) start first and get their arguments later (runtime.startup.Helpers): a stop before
they got them, while they start, or while the run waits for them leaves none of them behind.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from hofto_hw.recording.info import log_info
from hofto_hw.replay.flight_log import flight_metadata

#: the subprocess: wrap ``TARGET`` so that the signal is sent at it, run, report what is left
SCRIPT = textwrap.dedent(
    """
    import importlib, json, os, signal, sys
    from pathlib import Path

    module_name, attr, when, signum, argv = json.loads(sys.argv[1])
    owner = importlib.import_module(module_name)
    *path, name = attr.split(".")  # a function, or Class.method
    for part in path:
        owner = getattr(owner, part)
    real = getattr(owner, name)
    seen = {}

    def wrapped(*args, **kwargs):
        if "sent" not in seen:
            seen["sent"] = True
            if when == "before":
                os.kill(os.getpid(), signum)
                return real(*args, **kwargs)  # not reached: the signal raises at the kill
            out = real(*args, **kwargs)
            seen.update(args=args)
            os.kill(os.getpid(), signum)
            return out
        return real(*args, **kwargs)

    setattr(owner, name, wrapped)
    from hofto_hw.cli import main

    code = main(argv)
    left = {"sent": "sent" in seen, "enabled": None, "bus_open": None}
    if attr == "enable_drives" and "args" in seen:
        from drivers.cia402.state_machine import State

        bus, group = seen["args"]
        left["enabled"] = bool((group.states == State.OPERATION_ENABLED).any())
        left["bus_open"] = bool(bus.is_open)
    me = str(os.getpid())
    kids = []  # processes whose parent is this one (field 4 of /proc/PID/stat)
    for p in Path("/proc").iterdir():
        try:
            stat = (p / "stat").read_text()
        except OSError:
            continue
        if p.name.isdigit() and stat[stat.rindex(")") + 2 :].split()[1] == me:
            cmd = (p / "cmdline").read_text().replace(chr(0), " ")
            if "multiprocessing.resource_tracker" not in cmd:  # Python's; ends with us
                kids.append(f"{p.name}: {cmd}")
    left["children"] = kids
    left["shm"] = sorted(p.name for p in Path("/dev/shm").glob(f"hofto-hw-{me}-*"))
    print("LEFT " + json.dumps(left), flush=True)
    sys.exit(code)
    """
)


def _run_with_signal_at(
    tmp_path: Path, module: str, attr: str, when: str, signum: int = signal.SIGTERM
) -> tuple[int, str, dict]:
    sock = tmp_path / "control.sock"
    argv = ["run", "--clock", "sim", "--log-dir", str(tmp_path / "logs"), "--socket", str(sock)]
    env = {k: v for k, v in os.environ.items() if k != "NOTIFY_SOCKET"}
    res = subprocess.run(
        [sys.executable, "-c", SCRIPT, json.dumps([module, attr, when, int(signum), argv])],
        capture_output=True,
        text=True,
        timeout=900,
        env=env,
    )
    lines = [line for line in res.stdout.splitlines() if line.startswith("LEFT ")]
    assert lines, res.stdout + res.stderr[-3000:]
    left = json.loads(lines[-1][5:])
    assert left["sent"], "the wrapped start-up step was never reached"
    assert not sock.exists()  # the control socket was removed
    assert left["children"] == [], res.stderr  # control plane and log writer are gone
    assert left["shm"] == []  # the recorder's and the channel's shared memory
    return res.returncode, res.stderr, left


def _readable_log(tmp_path: Path) -> None:
    (log,) = (tmp_path / "logs").glob("*.mcap")
    info = log_info(log)
    assert info.complete  # the recorder closed it (its summary is written)
    assert flight_metadata(log) is not None


@pytest.mark.parametrize(
    ("module", "attr", "when", "phase"),
    [
        # while the kernels are compiled or loaded (the recorder and control plane run)
        ("hofto_hw.runtime.compose", "make_observer", "before", "kernels"),
        # inside a step that must finish first: the recorder's writer is started, then closed
        ("hofto_hw.commands.run", "_start_recorder", "before", "recorder"),
        ("hofto_hw.commands.run", "_start_control_plane", "before", "control plane"),
        # the drives were just enabled: they are disabled again and the bus closed
        ("hofto_hw.runtime.compose", "enable_drives", "after", "enabled"),
        # the helpers were sent their arguments and are still starting, or are awaited
        ("hofto_hw.runtime.startup", "Helpers.await_ready", "before", "helpers starting"),
        ("hofto_hw.runtime.startup", "Helpers.await_ready", "after", "helpers up"),
    ],
)
def test_sigterm_during_start_up_is_a_clean_stop(
    tmp_path: Path, module: str, attr: str, when: str, phase: str
) -> None:
    code, err, left = _run_with_signal_at(tmp_path, module, attr, when)
    assert code == 0, err[-3000:]
    assert "SIGTERM during start-up: stopped" in err, err[-3000:]
    assert "Traceback" not in err
    assert "running (pid" not in err  # the loop never ran
    _readable_log(tmp_path)
    if phase == "enabled":
        assert left["enabled"] is False and left["bus_open"] is False, left


def test_sigterm_before_the_helpers_got_their_arguments(tmp_path: Path) -> None:
    """The helper processes are forked before the config is read and wait for their
    arguments meanwhile: a stop then ends them, and no log is begun."""
    code, err, _ = _run_with_signal_at(
        tmp_path, "hofto_hw.commands.run", "_check_interface", "before"
    )
    assert code == 0, err[-3000:]
    assert "SIGTERM during start-up: stopped" in err and "Traceback" not in err, err[-3000:]
    assert not list((tmp_path / "logs").glob("*.mcap"))  # no log begun (none to close)


def test_sigint_during_start_up_exits_130(tmp_path: Path) -> None:
    code, err, _ = _run_with_signal_at(
        tmp_path, "hofto_hw.runtime.compose", "make_observer", "before", signal.SIGINT
    )
    assert code == 130, err[-3000:]
    assert "SIGINT during start-up: stopped" in err and "Traceback" not in err
    _readable_log(tmp_path)


@pytest.mark.slow
def test_sigterm_from_outside_while_a_cold_cache_compiles(tmp_path: Path) -> None:
    """systemctl stop during a first start: the signal comes from another process while the
    start-up says it compiles (an empty NUMBA_CACHE_DIR: tens of seconds of compiling)."""
    env = {k: v for k, v in os.environ.items() if k != "NOTIFY_SOCKET"}
    env["NUMBA_CACHE_DIR"] = str(tmp_path / "numba")
    proc = subprocess.Popen(
        [
            sys.executable,
            "-c",
            "import sys; from hofto_hw.cli import main; sys.exit(main())",
            "run",
            "--clock",
            "sim",
            "--log-dir",
            str(tmp_path / "logs"),
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )
    assert proc.stderr is not None
    said = []
    try:
        for line in proc.stderr:
            said.append(line)
            if "starting: loading the compiled kernels (compiling" in line:
                proc.send_signal(signal.SIGTERM)
                break
        _, rest = proc.communicate(timeout=600)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    err = "".join(said) + rest
    assert proc.returncode == 0, err[-3000:]
    assert "SIGTERM during start-up: stopped" in err and "Traceback" not in err, err[-3000:]
    assert "started in" not in err
    _readable_log(tmp_path)


def test_a_half_built_llvmlite_object_at_exit_says_nothing_after_a_start_up_stop(
    monkeypatch, capsys
) -> None:
    """The cold-compile SIGTERM test above once printed llvmlite's ``ObjectRef.__del__``
    AttributeError after the clean stop's line: an object the interrupted compile left half
    built. Those are dropped; an unraisable exception of anything else is still printed."""
    import sys
    import types

    from hofto_hw.commands import run as run_cmd

    seen = []
    monkeypatch.setattr(sys, "unraisablehook", lambda u: seen.append(u.object))
    run_cmd.quiet_interrupted_compile()

    def llvm_del() -> None: ...

    llvm_del.__module__ = "llvmlite.binding.ffi"

    def ours() -> None: ...

    for obj in (llvm_del, ours):
        sys.unraisablehook(types.SimpleNamespace(object=obj, exc_value=AttributeError("x")))
    assert seen == [ours]
