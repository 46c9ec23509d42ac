"""The product as a user installs it: the wheel, in a fresh venv outside the checkout, and the
service as its systemd unit runs it.

One wheel per session (``pip wheel``, pip's cache for the build requirements), installed with
``--no-deps`` into a fresh venv whose dependencies come from this test's own venv (a ``.pth``
line adds its site-packages after the new venv's own, so the wheel's hofto_hw, drivers and
safety are the ones imported, never the checkout's): a full dependency install takes minutes
here. Every command runs from a folder outside the checkout. ``HOFTO_HW_TEST_WHEEL=FILE`` uses
a wheel built already (of this tree) instead of building one (~40 s of CPU).

The deployment tests run configs/systemd/hofto-hw.service's ExecStart with its environment:
as an unprivileged user (nobody, via setpriv, with the unit's ambient capabilities), no home,
only the log, runtime and cache folders writable, NUMBA_CACHE_DIR as the unit sets it, and a
NOTIFY_SOCKET that this test reads (READY). They need root for that (skip without it, fail
under CI) and check: the compiled tick is the one running (the "running" line, ``hofto-hw
status``, the log's metadata), SIGTERM ends it with exit 0 and a readable log, and the second
start compiles nothing (numba's cache files untouched). The start-up times to READY are
printed (``-s``); they are benchmarks, not asserted.
"""

from __future__ import annotations

import configparser
import json
import os
import shlex
import shutil
import signal
import socket
import subprocess
import sys
import sysconfig
import tempfile
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import pytest
import yaml
from support.rootnet import emulator, require_root, sim_ethercat_args, veth_pair, wait_for

pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[1]
UNIT = ROOT / "configs" / "systemd" / "hofto-hw.service"
INSTALLED = "/opt/hofto-hw/bin/hofto-hw"
#: a start-up may compile every kernel (cold numba cache) on a loaded 2-core machine
START_TIMEOUT = 900.0
NOBODY = 65534
#: what a checkout holds besides its sources
BUILD_LEFTOVERS = (".git", ".venv", "build", "dist", "out", "*.egg-info", "__pycache__", "*.so")


@dataclass
class Install:
    """The wheel installed in a fresh venv (world-readable, outside the checkout)."""

    wheel: Path
    venv: Path
    work: Path  # the cwd of every command: an empty folder outside the checkout

    @property
    def bin(self) -> Path:
        return self.venv / "bin"

    def run(self, *args: str, timeout: float = START_TIMEOUT) -> subprocess.CompletedProcess:
        """``hofto-hw ARGS`` of this install, from ``work``, without PYTHONPATH."""
        env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
        return subprocess.run(
            [str(self.bin / "hofto-hw"), *args],
            cwd=self.work,
            env=env,
            capture_output=True,
            text=True,
            timeout=timeout,
        )

    def python(self, code: str) -> str:
        env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
        out = subprocess.run(
            [str(self.bin / "python"), "-c", code],
            cwd=self.work,
            env=env,
            capture_output=True,
            text=True,
            timeout=300,
            check=True,
        )
        return out.stdout.strip()


def _interpreter() -> str:
    """The Python for the fresh venv: this one, unless we are root and the system's
    /usr/bin/python3 has this version (the deployment tests run the venv as nobody, who may
    not reach this interpreter, e.g. one under /root)."""
    system = Path("/usr/bin/python3")
    if os.geteuid() == 0 and system.is_file():
        version = subprocess.run(
            [str(system), "-c", "import sys; print(sys.version_info[:2])"],
            capture_output=True,
            text=True,
            timeout=60,
        ).stdout.strip()
        if version == str(tuple(sys.version_info[:2])):
            return str(system)
    return sys.executable


@pytest.fixture(scope="module")
def install() -> Iterator[Install]:
    top = Path(tempfile.mkdtemp(prefix="hofto-hw-install-"))
    top.chmod(0o755)  # the deployment tests run the install as nobody
    try:
        given = os.environ.get("HOFTO_HW_TEST_WHEEL")  # a wheel built already (of this tree)
        dist = top / "dist"
        if given:
            dist.mkdir()
            shutil.copy(given, dist)
        # the sources alone (no build/ of an earlier build: its files would go into the wheel)
        src = top / "src"
        shutil.copytree(ROOT, src, ignore=shutil.ignore_patterns(*BUILD_LEFTOVERS))
        t0 = time.monotonic()
        if not given:
            built = subprocess.run(
                [
                    sys.executable,
                    "-m",
                    "pip",
                    "wheel",
                    "--no-deps",
                    "-q",
                    "-w",
                    str(dist),
                    str(src),
                ],
                capture_output=True,
                text=True,
                timeout=3600,
            )
            assert built.returncode == 0, built.stderr[-4000:]  # the build's own last lines
        (wheel,) = dist.glob("hofto_hw-*.whl")
        print(
            f"\nwheel {wheel.name}: {wheel.stat().st_size / 1e6:.2f} MB, built in "
            f"{time.monotonic() - t0:.0f} s"
        )
        venv = top / "venv"
        subprocess.run([_interpreter(), "-m", "venv", str(venv)], check=True, timeout=600)
        site = Path(
            subprocess.run(
                [
                    str(venv / "bin" / "python"),
                    "-c",
                    "import sysconfig; print(sysconfig.get_paths()['purelib'])",
                ],
                check=True,
                capture_output=True,
                text=True,
            ).stdout.strip()
        )
        # this venv's dependencies, after the new venv's own packages (.pth files included:
        # pinocchio's cmeel prefix is one)
        ours = sysconfig.get_paths()["purelib"]
        (site / "zz_test_dependencies.pth").write_text(f"import site; site.addsitedir({ours!r})\n")
        subprocess.run(
            [str(venv / "bin" / "python"), "-m", "pip", "install", "-q", "--no-deps", str(wheel)],
            check=True,
            timeout=600,
        )
        work = top / "work"
        work.mkdir()
        yield Install(wheel, venv, work)
    finally:
        shutil.rmtree(top, ignore_errors=True)


def test_wheel_ships_the_native_library_and_the_configs(install: Install) -> None:
    import zipfile

    names = zipfile.ZipFile(install.wheel).namelist()
    assert any(n.startswith("hofto_hw/model/native/_dynamics") and n.endswith(".so") for n in names)
    assert "hofto_hw/robot_configs/er3a.yaml" in names
    assert "hofto_hw/robot_configs/er3a/er3a.urdf" in names
    assert "hofto_hw/robot_configs/systemd/hofto-hw.service" in names
    assert not any(n.endswith(".cpp") for n in names)  # built, not built again
    where = install.python(
        "import hofto_hw, drivers, safety; from hofto_hw.model import native; "
        "from hofto_hw.config.locate import PROJECT_CONFIGS; "
        "print(hofto_hw.__file__, drivers.__file__, safety.__file__, native.ready(), "
        "PROJECT_CONFIGS)"
    )
    *files, ready, configs = where.split()
    for f in [*files, configs]:
        assert Path(f).is_relative_to(install.venv), f  # nothing from the checkout
    assert ready == "True"


def test_installed_config_check_and_run_by_robot_name(install: Install) -> None:
    res = install.run("config", "check", "er3a", "er3a_service")
    assert res.returncode == 0, res.stderr
    assert "er3a.yaml: ok" in res.stdout and "er3a_service.yaml: ok" in res.stdout
    res = install.run("run", "--clock", "sim", "--summary-json", "summary.json")
    assert res.returncode == 0, res.stderr[-3000:]
    summary = json.loads((install.work / "summary.json").read_text())
    assert summary["acceleration"]["compiled"] is True, summary["acceleration"]
    assert summary["observers"]["hofto"] is not None  # the scripted contact was detected
    assert "collision" in [e["kind"] for e in summary["events"]]
    assert summary["drag"]["steady_speed_mps"] is not None
    assert "real-time" not in res.stderr  # no real-time warning for the sim clock
    assert "tick: compiled" in res.stdout
    # the shipped config's ../out/logs is the working directory's out/logs, not the package's
    assert list((install.work / "out" / "logs").glob("*.mcap"))
    package = Path(install.python("import hofto_hw; print(hofto_hw.__file__)").strip()).parent
    assert not (package / "out").exists() and not (package.parent / "out").exists()


# ------------------------------------------------------------------------- deployment


def unit_service() -> dict[str, list[str]]:
    """The unit's [Service] keys, every value of a repeated key kept."""
    out: dict[str, list[str]] = {}
    for line in UNIT.read_text().splitlines():
        line = line.strip()
        if line and not line.startswith(("#", "[")) and "=" in line:
            key, value = line.split("=", 1)
            out.setdefault(key, []).append(value)
    parser = configparser.ConfigParser(strict=False, interpolation=None)
    parser.read_string(UNIT.read_text())  # well-formed as an INI file too
    return out


class Notify:
    """An sd_notify datagram socket (what systemd gives a Type=notify service): records the
    time each message arrived."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
        self.sock.bind(str(path))
        path.chmod(0o777)
        self.messages: list[tuple[float, str]] = []
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        while True:
            try:
                data = self.sock.recv(4096)
            except OSError:
                return
            self.messages.append((time.monotonic(), data.decode(errors="replace")))

    def ready_at(self) -> float | None:
        return next((t for t, m in self.messages if "READY=1" in m.split("\n")), None)

    def close(self) -> None:
        self.sock.close()


@dataclass
class Service:
    """The unit's ExecStart of ``install`` as nobody, in a private set of folders."""

    install: Install
    top: Path
    config: Path
    env: dict[str, str] = field(default_factory=dict)
    proc: subprocess.Popen | None = None
    stderr: list[str] = field(default_factory=list)
    logs_before: set[Path] = field(default_factory=set)

    @property
    def socket(self) -> Path:
        return self.top / "run" / "control.sock"

    @property
    def logs(self) -> Path:
        return self.top / "log"

    @property
    def cache(self) -> Path:
        return self.top / "cache"

    def argv(self) -> list[str]:
        s = unit_service()
        (exec_start,) = s["ExecStart"]
        argv = shlex.split(exec_start)
        assert argv[0] == INSTALLED and "/etc/hofto-hw/robot.yaml" in argv
        swap = {
            INSTALLED: str(self.install.bin / "hofto-hw"),
            "/etc/hofto-hw/robot.yaml": str(self.config),
            "/run/hofto-hw/control.sock": str(self.socket),
        }
        caps = ",".join(
            "+" + c.removeprefix("CAP_").lower() for c in s["AmbientCapabilities"][0].split()
        )
        user = ["setpriv", f"--reuid={NOBODY}", f"--regid={NOBODY}", "--clear-groups"]
        user += [f"--inh-caps={caps}", f"--ambient-caps={caps}"]
        return [*user, *(swap.get(a, a) for a in argv)]

    def unit_env(self, notify: Path) -> dict[str, str]:
        env = {"PATH": "/usr/bin:/bin", "LANG": "C.UTF-8", "HOME": "/nonexistent"}
        env["NOTIFY_SOCKET"] = str(notify)
        for item in unit_service().get("Environment", []):
            for word in shlex.split(item):
                key, value = word.split("=", 1)
                env[key] = value.replace("/var/cache/hofto-hw", str(self.cache))
        return env

    def start(self) -> float:
        """Start and wait for READY; returns the seconds from exec to READY."""
        self.stderr = []
        self.logs_before = set(self.logs.glob("*.mcap"))
        notify = Notify(self.top / f"notify-{len(list(self.top.glob('notify-*')))}")
        t0 = time.monotonic()
        self.proc = subprocess.Popen(
            self.argv(),
            cwd="/",
            env=self.unit_env(notify.path),
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        threading.Thread(target=self._read_stderr, daemon=True).start()
        try:
            wait_for(lambda: notify.ready_at() is not None, START_TIMEOUT, "READY", self.proc)
        except AssertionError as exc:
            raise AssertionError(f"{exc}: {''.join(self.stderr)[-3000:]}") from None
        finally:
            notify.close()
        wait_for(self.socket.exists, 60, "the control socket", self.proc)
        ready = notify.ready_at()
        assert ready is not None
        return ready - t0

    def _read_stderr(self) -> None:
        assert self.proc is not None and self.proc.stderr is not None
        for line in self.proc.stderr:
            self.stderr.append(line)

    def status(self) -> dict:
        res = self.install.run("status", "--json", "--socket", str(self.socket), timeout=60)
        assert res.returncode == 0, res.stderr
        return json.loads(res.stdout)

    def terminate(self) -> tuple[int, str]:
        """SIGTERM (systemctl stop); the exit code and stdout."""
        assert self.proc is not None
        self.proc.send_signal(signal.SIGTERM)
        try:
            out, _ = self.proc.communicate(timeout=120)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.communicate()
            raise AssertionError("no exit within 120 s of SIGTERM") from None
        return self.proc.returncode, out


def service_folders(install: Install, bus: dict) -> tuple[Path, Path]:
    """A folder tree for the unit (log, run, cache owned by nobody; etc read-only) and the
    installed er3a_service.yaml with ``bus`` and no CPU latency request, as robot.yaml."""
    top = Path(tempfile.mkdtemp(prefix="hofto-hw-unit-", dir=install.venv.parent))
    top.chmod(0o755)
    for name in ("log", "run", "cache"):
        (top / name).mkdir()
        os.chown(top / name, NOBODY, NOBODY)
    (top / "run").chmod(0o750)
    shipped = Path(
        install.python("from hofto_hw.config.locate import PROJECT_CONFIGS; print(PROJECT_CONFIGS)")
    )
    data = yaml.safe_load((shipped / "er3a_service.yaml").read_text())
    assert data["run"]["duration"] is None and data["run"]["collision"] is None
    assert data["loop"]["acceleration"] == "required"
    data["robot"]["urdf"] = str(shipped / data["robot"]["urdf"])
    data["bus"].update(bus)
    data["loop"]["cpu_latency_us"] = None  # a shared machine: no global PM QoS request
    data["safety"]["overrun_streak"] = 1000  # host stalls are not what this tests
    data["safety"]["bus"]["lost_cycles"] = 50
    data["run"]["log_dir"] = str(top / "log")
    etc = top / "etc"
    etc.mkdir()
    config = etc / "robot.yaml"
    config.write_text(yaml.safe_dump(data))
    return top, config


def numba_cache(folder: Path) -> dict[str, tuple[int, int]]:
    return {
        str(p): (p.stat().st_mtime_ns, p.stat().st_size) for p in folder.rglob("*") if p.is_file()
    }


def check_stop(svc: Service) -> None:
    """SIGTERM -> exit 0, a summary naming the compiled tick, a readable log of this run."""
    code, out = svc.terminate()
    assert code == 0, "".join(svc.stderr)[-3000:]
    assert "tick: compiled" in out, out
    (log,) = set(svc.logs.glob("*.mcap")) - svc.logs_before
    res = svc.install.run("log", "info", "--json", str(log), timeout=120)
    assert res.returncode == 0, res.stderr
    info = json.loads(res.stdout)
    meta = info["metadata"]
    assert any(m.get("acceleration") == "compiled" for m in meta.values()), meta


def test_service_as_the_unit_runs_it_on_the_simulated_bus(install: Install) -> None:
    require_root("running the unit's ExecStart as an unprivileged user (setpriv)")
    top, config = service_folders(install, {"transport": "sim"})
    svc = Service(install, top, config)
    try:
        cold = svc.start()
        assert any("tick: compiled" in line for line in svc.stderr), svc.stderr
        s = svc.status()
        assert s["state"] in ("running", "enabling") and s["acceleration"]["compiled"], s
        assert s["faults"] == []
        check_stop(svc)
        cache = numba_cache(svc.cache)
        assert cache, "numba wrote no cache into NUMBA_CACHE_DIR"
        warm = svc.start()
        assert svc.status()["acceleration"]["compiled"]
        check_stop(svc)
        assert numba_cache(svc.cache) == cache  # the second start compiled nothing
        print(f"\nservice start-up to READY: first {cold:.1f} s, second (warm cache) {warm:.1f} s")
    finally:
        if svc.proc is not None and svc.proc.poll() is None:
            svc.proc.kill()
            svc.proc.wait()
        shutil.rmtree(top, ignore_errors=True)


def test_service_as_the_unit_runs_it_over_ethercat(install: Install) -> None:
    require_root("veth pairs, raw sockets and the unit's unprivileged user")
    with veth_pair() as (master, slave):
        top, config = service_folders(
            install,
            {"transport": "ethercat", "interface": master, "ethercat": {"pdo_watchdog": 2.0}},
        )
        svc = Service(install, top, config)
        emu_dir = top / "emulator"
        emu_dir.mkdir()
        try:
            with emulator(sim_ethercat_args(slave, ROOT / "configs" / "er3a.yaml"), emu_dir):
                took = svc.start()
                s = svc.status()
                assert s["acceleration"]["compiled"] and s["faults"] == [], s
                check_stop(svc)
                print(f"\nservice over EtherCAT: READY after {took:.1f} s")
        finally:
            if svc.proc is not None and svc.proc.poll() is None:
                svc.proc.kill()
                svc.proc.wait()
            shutil.rmtree(top, ignore_errors=True)
