"""The drive group's read/command, its one implementation the kernels of
drivers/cia402/kernels.py (compiled, and their Python source), against the numpy reference
(tests/drivers/cia402/reference.py: drivers/cia402/units.py's vector conversions): the same
raw image gives the same SI values, the same SI command the same raw image, bit for bit,
saturation and NaN included."""

from __future__ import annotations

import importlib.util
import tracemalloc
from pathlib import Path

import numpy as np
import pytest

from drivers.cia402.drive_group import DriveGroup
from drivers.cia402.state_machine import Mode, State
from drivers.sim.simbus import SimBus
from hofto_hw import jit as observer_jit
from hofto_hw.config.models import SystemConfig

pytestmark = pytest.mark.skipif(
    not observer_jit.available(), reason=observer_jit.unavailable_reason() or "numba"
)

# the reference by its path (tests/drivers is not a package: `drivers` is the product's)
_spec = importlib.util.spec_from_file_location(
    "cia402_reference", Path(__file__).with_name("reference.py")
)
reference = importlib.util.module_from_spec(_spec)  # type: ignore[arg-type]
_spec.loader.exec_module(reference)  # type: ignore[union-attr]


@pytest.fixture
def pair(bus: SimBus, cfg: SystemConfig) -> tuple[DriveGroup, DriveGroup]:
    """The kernels as Python source and compiled, two drive groups over the same (opened)
    process image."""
    bus.open()
    ref = DriveGroup.from_config(bus, cfg.bus, backend="python")
    fast = DriveGroup.from_config(bus, cfg.bus, backend="numba")
    assert ref.backend == "python" and fast.backend == "numba"
    assert ref._fast is None and fast._fast is not None  # what the tick's fused call checks
    return ref, fast


def _random_tx(tx: np.ndarray, rng: np.random.Generator) -> None:
    n = tx.shape[0]
    i32, i16 = np.iinfo(np.int32), np.iinfo(np.int16)
    tx["position"] = rng.integers(i32.min, i32.max, n, endpoint=True)
    tx["velocity"] = rng.integers(i32.min, i32.max, n, endpoint=True)
    tx["torque"] = rng.integers(i16.min, i16.max, n, endpoint=True)
    tx["current"] = rng.integers(i16.min, i16.max, n, endpoint=True)
    tx["statusword"] = rng.integers(0, 0xFFFF, n, endpoint=True)


def test_read_agrees_with_the_numpy_reference(pair: tuple[DriveGroup, DriveGroup]) -> None:
    py, fast = pair
    tx = py.transport.tx
    rng = np.random.default_rng(11)
    for k in range(3000):
        _random_tx(tx, rng)
        if k % 7 == 0:  # the extremes of each raw type
            tx["position"][k % py.n] = np.iinfo(np.int32).min
            tx["torque"][(k + 1) % py.n] = np.iinfo(np.int16).min
        want = reference.read(py)
        for g in (fast, py) if k % 10 == 0 else (fast,):  # the interpreter's source: slower
            g.read()
            for name in reference.READ_FIELDS:
                np.testing.assert_array_equal(getattr(g, name), want[name], err_msg=name)
    assert len(set(py.states.tolist())) > 1 and np.any(py.q != 0.0)


def _random_si(rng: np.random.Generator, n: int, scale: float) -> np.ndarray:
    x = rng.normal(0.0, scale, n)
    kind = rng.integers(0, 8)
    if kind == 0:
        x[rng.integers(n)] = np.nan
    elif kind == 1:
        x[rng.integers(n)] = rng.choice([np.inf, -np.inf, 1e300, -1e300])
    elif kind == 2:
        x[rng.integers(n)] = -0.0
    return x


def test_commands_agree_with_the_numpy_reference(pair: tuple[DriveGroup, DriveGroup]) -> None:
    py, fast = pair
    rx = py.transport.rx
    n = py.n
    rng = np.random.default_rng(12)
    fields = ("target_position", "target_velocity", "torque_offset")
    with np.errstate(invalid="ignore"):  # numpy's cast of NaN warns; the kernel does not
        for k in range(3000):
            # positions up to saturation, torques up to the per-mille range and beyond
            target = _random_si(rng, n, 10.0 ** rng.uniform(-3, 4))
            tau = _random_si(rng, n, 10.0 ** rng.uniform(-2, 4))
            if k % 5 == 0:  # exact halves of a count: round half to even on both paths
                counts = rng.integers(-1000, 1000, n) + 0.5
                target = (counts - py.scaling.zero_offset) / py.scaling.count_per_rad
            off = tau if k % 3 else None
            for command in ("command_position", "command_velocity"):
                rx[list(fields)] = 0
                reference.command(py, command, target, off)
                want = rx.copy()
                for g in (fast, py) if k % 10 == 0 else (fast,):
                    rx[list(fields)] = 0
                    getattr(g, command)(target, off)
                    for f in fields:
                        np.testing.assert_array_equal(
                            rx[f], want[f], err_msg=f"{g.backend} {command} {f}"
                        )


def test_compiled_group_enables_and_holds_over_the_simulated_bus(
    bus: SimBus, cfg: SystemConfig
) -> None:
    bus.open()
    g = DriveGroup.from_config(bus, cfg.bus, backend="auto")
    assert g.backend == "numba"
    g.configure(cfg.bus.drives)
    g.set_mode(Mode.CSP)
    g.enable()
    assert g.all_in(State.OPERATION_ENABLED)
    q0 = g.q.copy()
    for k in range(300):
        g.command_position(q0 + 0.05 * min(1.0, k / 100), np.zeros(g.n))
        g.cycle()
    assert np.allclose(bus.plant.q, q0 + 0.05, atol=3e-3)
    assert np.allclose(g.q, bus.plant.q, atol=2e-6)  # the compiled SI decode of the counts


def test_compiled_read_and_commands_do_not_allocate(pair: tuple[DriveGroup, DriveGroup]) -> None:
    _, g = pair
    q = np.zeros(g.n)
    g.read()
    g.command_position(q, q)
    g.command_velocity(q)
    tracemalloc.start()
    for _ in range(200):
        g.read()
        g.command_position(q, q)
        g.command_velocity(q, q)
    before, _ = tracemalloc.get_traced_memory()
    for _ in range(2000):
        g.read()
        g.command_position(q, q)
        g.command_velocity(q, q)
    after, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    assert after - before < 500  # nothing kept per call
    assert peak - before < 2000  # no arrays created per call


def test_the_sample_is_one_block_the_limit_monitor_reads_in_place(
    pair: tuple[DriveGroup, DriveGroup],
) -> None:
    """q, qd, tau stay views of one workspace across reads: the tick's compiled limit scan
    then takes them as one (3, n) argument instead of copying them."""
    from tests.support.reference_safety import rows_of_one_block

    for g in pair:
        q, qd, tau = g.q, g.qd, g.tau
        g.read()
        assert g.q is q and g.qd is qd and g.tau is tau
        block = rows_of_one_block(q, qd, tau)
        assert block is not None and np.shares_memory(block, g.sample)
        np.testing.assert_array_equal(block, g.sample)


def test_image_bytes_refuses_what_is_not_a_contiguous_process_image() -> None:
    from drivers.cia402.kernels import image_bytes
    from drivers.cia402.pdo import new_rx, new_tx

    tx = new_tx(4)
    assert image_bytes(tx).shape == (4 * tx.dtype.itemsize,)
    assert np.shares_memory(image_bytes(tx), tx)
    with pytest.raises(ValueError, match="not a contiguous process image"):
        image_bytes(new_rx(6)[::2])
    with pytest.raises(ValueError, match="not a contiguous process image"):
        image_bytes(np.zeros(6))


def test_the_kernels_literal_layout_is_the_pdo_modules(
    monkeypatch: pytest.MonkeyPatch, bus: SimBus, cfg: SystemConfig
) -> None:
    """The compiled read/command bake the PDO byte offsets and the statusword table into
    their cached machine code (numba does not see changes in other files): the literals in
    drivers/cia402/kernels.py must be pdo.py's and state_machine.py's, and a group whose
    layout differs is refused rather than decoding the wrong bytes."""
    from drivers.cia402 import kernels

    assert kernels.layout_matches()
    monkeypatch.setattr(kernels, "_TX_VEL", 8)
    assert not kernels.layout_matches()
    monkeypatch.undo()
    table = kernels._STATE_TABLE.copy()
    table[5] ^= 1
    monkeypatch.setattr(kernels, "_STATE_TABLE", table)
    assert not kernels.layout_matches()
    assert not kernels.ready("numba", lambda: None)
    for backend in ("python", "numba"):  # the kernels' source reads the same literals
        with pytest.raises(RuntimeError, match="layout literals"):
            DriveGroup.from_config(bus, cfg.bus, backend=backend)  # type: ignore[arg-type]


def test_without_numba_the_group_runs_the_kernels_source_and_compiles_nothing(
    tmp_path: Path,
) -> None:
    """HOFTO_HW_NO_NUMBA=1 (numba's switch of this project, read at import): the group runs
    the kernels' Python source, byte helpers included (none is compiled on the way), and
    reads the same SI values the numpy reference gives."""
    import os
    import subprocess
    import sys

    root = Path(__file__).resolve().parents[3]
    reference_py = str(Path(__file__).with_name("reference.py"))
    script = f"""
import importlib.util, numpy as np
from hofto_hw.config import load_config
from hofto_hw.runtime.build import build_sim_bus
from drivers.cia402.drive_group import DriveGroup
from drivers.cia402 import kernels
spec = importlib.util.spec_from_file_location("ref", {reference_py!r})
ref = importlib.util.module_from_spec(spec); spec.loader.exec_module(ref)
cfg = load_config({str(root / "configs" / "er3a.yaml")!r})
bus = build_sim_bus(cfg, external=False)
bus.open()
g = DriveGroup.from_config(bus, cfg.bus)
assert g.backend == "python" and g._fast is None, g.backend
bus.tx["position"] = [1000, -2000, 3, 2**31 - 1, -2**31, 0]
bus.tx["statusword"] = [0x0237, 0x0250, 0x0208, 0x0233, 0x0231, 0x0240]
g.read()
g.command_position(np.full(6, 0.1), np.full(6, 2.0))
want = ref.read(g)
for f in ref.READ_FIELDS:
    assert np.array_equal(getattr(g, f), want[f]), f
assert bus.rx["target_position"].any() and bus.rx["torque_offset"].any()
fns = ("read_si", "command_raw", "_u16", "_i16", "_i32", "_put", "_to_raw")
compiled = [f for f in fns if getattr(getattr(kernels, f), "signatures", None)]
assert not compiled, compiled
print("ok")
"""
    env = {**os.environ, "HOFTO_HW_NO_NUMBA": "1"}
    out = subprocess.run(
        [sys.executable, "-c", script], cwd=tmp_path, env=env, capture_output=True, text=True,
        timeout=120,
    )  # fmt: skip
    assert out.returncode == 0 and out.stdout.strip() == "ok", out.stderr[-2000:]
