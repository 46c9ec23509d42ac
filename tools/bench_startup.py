"""Service start-up to READY, cold and warm, and where the time goes.

Starts ``hofto-hw run`` as configs/systemd/hofto-hw.service does (``--clock real --socket S``,
a ``NOTIFY_SOCKET`` this script reads, ``NUMBA_CACHE_DIR`` in a folder of its own) on
configs/er3a_service.yaml with the simulated bus, waits for READY, stops it with SIGTERM (exit
0 expected), and repeats: the first start compiles every kernel into the empty cache (cold),
the later ones load it (warm). Each start's phases come from its progress lines
(HOFTO_HW_PROGRESS_AFTER=0: each phase's line is printed as it begins; timed by arrival):
the interpreter, the CLI, every import and the forking of the helper processes (before the
first line), config, native library, flight recorder and control plane (their shared memory
and arguments sent), kernels (numba's cache), awaiting the writer's first file and the control
plane's start, bus, safety and tick, enabling, then the first tick and READY. ``--imports``
adds ``python -X importtime`` of the run command's imports, summed by top-level package (self
time). Prints medians of the warm starts, the 1-minute load average before and after;
``--json`` prints everything as JSON.

    python tools/bench_startup.py                 # 1 cold + 5 warm starts
    python tools/bench_startup.py --warm 3 --no-cold --imports --json

The service's own installation runs the installed wheel (tests/test_install.py prints its
cold and warm figures too); this runs the Python that runs it, from the checkout or a venv.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PHASE = re.compile(r"^hofto-hw run: starting: (.*) \((\d+(?:\.\d+)?) s\)$")
STARTED = re.compile(r"^hofto-hw run: started in (\d+(?:\.\d+)?) s$")
#: short names of the phases hofto_hw/commands/run.py and runtime/compose.py announce
SHORT = {
    "importing": "imports",
    "reading the config": "config",
    "loading the native": "native library",
    "starting the flight recorder": "flight recorder",
    "starting the control plane": "control plane",
    "loading the compiled kernels": "kernels",
    "opening the bus": "bus",
    "loading the safety checks": "safety and tick",
    "collecting garbage": "gc",
    "enabling the drives": "enable",
    "waiting for the flight recorder": "awaiting the writer",
    "waiting for the control plane": "awaiting the control plane",
}


def _short(text: str) -> str:
    return next((v for k, v in SHORT.items() if text.startswith(k)), text)


def _config(folder: Path) -> Path:
    """er3a_service.yaml on the simulated bus, its log in ``folder``, no PM QoS request."""
    import yaml

    from hofto_hw.config.locate import find_config

    src = find_config("er3a_service")
    data = yaml.safe_load(src.read_text())
    data["robot"]["urdf"] = str((src.parent / data["robot"]["urdf"]).resolve())
    data["bus"]["transport"] = "sim"
    data["loop"]["cpu_latency_us"] = None  # a shared machine: no global request
    data["run"]["log_dir"] = str(folder / "log")
    out = folder / "robot.yaml"
    out.write_text(yaml.safe_dump(data))
    return out


def start_once(folder: Path, config: Path, cache: Path, n: int, timeout: float) -> dict:
    """One start to READY and its stop; the phases [s] and the totals."""
    notify_path = folder / f"notify-{n}"
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    sock.bind(str(notify_path))
    sock.settimeout(0.2)
    control = folder / f"control-{n}.sock"
    env = {k: v for k, v in os.environ.items() if not k.startswith(("HOFTO_HW_NO", "NUMBA_D"))}
    env.update(
        NOTIFY_SOCKET=str(notify_path),
        NUMBA_CACHE_DIR=str(cache),
        HOFTO_HW_PROGRESS_AFTER="0",
    )
    argv = ["run", "--config", str(config), "--clock", "real", "--socket", str(control)]
    code = "import sys; from hofto_hw.cli import main; sys.exit(main())"
    lines: list[tuple[float, str]] = []
    t0 = time.monotonic()
    proc = subprocess.Popen(
        [sys.executable, "-c", code, *argv],
        cwd=folder,
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )

    def read() -> None:
        assert proc.stderr is not None
        for line in proc.stderr:
            lines.append((time.monotonic() - t0, line.rstrip("\n")))

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    ready = None
    try:
        while ready is None and time.monotonic() - t0 < timeout:
            try:
                msg = sock.recv(4096).decode(errors="replace")
            except TimeoutError:
                if proc.poll() is not None:
                    break
                continue
            if "READY=1" in msg.split("\n"):
                ready = time.monotonic() - t0
        if ready is None:
            text = "\n".join(line for _, line in lines[-20:])
            raise SystemExit(f"bench_startup: no READY within {timeout:g} s:\n{text}")
        proc.send_signal(signal.SIGTERM)
        proc.wait(timeout=120)  # stderr is the reader thread's (the summary fits stdout's pipe)
        reader.join(timeout=10)
    finally:
        sock.close()
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    if proc.returncode != 0:
        raise SystemExit(f"bench_startup: exit {proc.returncode} after SIGTERM (expected 0)")
    # each phase from the arrival of its line to the next one's (HOFTO_HW_PROGRESS_AFTER=0:
    # a phase's line is printed as it begins; the times in the lines have 0.1 s steps)
    phases: list[tuple[str, float]] = []
    started = None
    for at, line in lines:
        m = PHASE.match(line)
        if m:
            phases.append((_short(m.group(1)), at))
        elif STARTED.match(line):
            started = at
    if started is None or not phases:
        raise SystemExit("bench_startup: no progress lines (HOFTO_HW_PROGRESS_AFTER ignored?)")
    # before the first line: the interpreter, the CLI, every import of the start-up and the
    # forking of the helper processes (hofto_hw.commands.run)
    out: dict[str, float] = {"interpreter, CLI, imports": round(phases[0][1], 3)}
    ends = [t for _, t in phases[1:]] + [started]
    for (name, t), end in zip(phases, ends, strict=True):
        out[name] = round(out.get(name, 0.0) + end - t, 3)
    out["first tick to READY"] = round(ready - started, 3)
    return {"ready_s": round(ready, 3), "phases_s": out}


def imports_by_package() -> dict[str, float]:
    """``python -X importtime`` of the run command's imports: self time [s] per top-level
    package, largest first."""
    code = (
        "import hofto_hw.commands.run, hofto_hw.config, hofto_hw.config.locate, "
        "hofto_hw.control.joint_motion, hofto_hw.runtime.acceleration, "
        "hofto_hw.runtime.compose, hofto_hw.runtime.drag_script, hofto_hw.runtime.summary, "
        "hofto_hw.recording.recorder, hofto_hw.control_plane.process"
    )
    res = subprocess.run(
        [sys.executable, "-X", "importtime", "-c", code],
        capture_output=True,
        text=True,
        timeout=600,
        check=True,
    )
    total: dict[str, float] = {}
    for line in res.stderr.splitlines():
        parts = line.split("|")
        if len(parts) != 3 or not parts[0].startswith("import time:"):
            continue
        try:
            own = int(parts[0].split(":")[1])
        except ValueError:
            continue  # the header line
        top = parts[2].strip().split(".")[0]
        total[top] = total.get(top, 0.0) + own * 1e-6
    ranked = sorted(total.items(), key=lambda kv: -kv[1])
    return {k: round(v, 3) for k, v in ranked[:12]}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--warm", type=int, default=5, help="warm starts (default 5)")
    ap.add_argument("--no-cold", action="store_true", help="no cold start first (the cache "
                    "is then filled by an unmeasured start)")  # fmt: skip
    ap.add_argument("--imports", action="store_true", help="import time by package")
    ap.add_argument("--timeout", type=float, default=900.0, help="per start [s]")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    if args.warm < 1:
        ap.error("--warm: at least 1")
    load_before = os.getloadavg()[0]
    with tempfile.TemporaryDirectory(prefix="bench-startup-") as tmp:
        folder = Path(tmp)
        (folder / "log").mkdir()
        config = _config(folder)
        cache = folder / "numba"
        cold = start_once(folder, config, cache, 0, args.timeout)
        warm = [start_once(folder, config, cache, i + 1, args.timeout) for i in range(args.warm)]
    imports = imports_by_package() if args.imports else None
    names = list(warm[0]["phases_s"])
    median = {
        k: round(statistics.median(w["phases_s"].get(k, 0.0) for w in warm), 3) for k in names
    }
    result = {
        "load_1min_before": round(load_before, 2),
        "load_1min_after": round(os.getloadavg()[0], 2),
        "cold": None if args.no_cold else cold,
        "warm": warm,
        "warm_ready_median_s": round(statistics.median(w["ready_s"] for w in warm), 3),
        "warm_phases_median_s": median,
        "imports_self_s": imports,
    }
    if args.json:
        print(json.dumps(result, indent=2))
        return 0
    print(f"load (1 min) {result['load_1min_before']} before, {result['load_1min_after']} after")
    if not args.no_cold:
        print(f"cold start to READY: {cold['ready_s']:.2f} s")
    ready = ", ".join(f"{w['ready_s']:.2f}" for w in warm)
    print(f"warm starts to READY: {ready} s; median {result['warm_ready_median_s']:.2f} s")
    print(f"{'phase':<24} {'warm median [s]':>16}" + ("" if args.no_cold else f" {'cold [s]':>9}"))
    for k in names:
        c = "" if args.no_cold else f" {cold['phases_s'].get(k, 0.0):>9.2f}"
        print(f"{k:<24} {median[k]:>16.2f}{c}")
    if imports:
        print(
            "import self time by package [s]: " + ", ".join(f"{k} {v}" for k, v in imports.items())
        )
    return 0


if __name__ == "__main__":
    sys.path.insert(0, str(ROOT))
    raise SystemExit(main())
