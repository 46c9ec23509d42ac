"""What an argument costs in a compiled (numba) call from Python: the representation choice for
the tick's kernels (drivers/cia402, safety, the demo path).

The same trivial kernel (n = 6 joints: out[j] = sum of k input rows) is called with its k
inputs as k separate 1-D arrays, one 2-D array whose rows are the inputs, a tuple of k
arrays, a numba jitclass and a structref holding the k arrays, and with scalar (float, bool)
arguments beside one array. Each variant is timed alone (back to back, warm caches) and
"flushed": after sweeping an 8 MiB buffer and some Python work that evicts the caches, as the
simulated bus's exchange does in the tick. The variants are interleaved in blocks so that
the machine's load hits all alike. Figures: median µs per call (the timer's own cost, an
empty timed block, is subtracted). Timing goals live here, never in tests.

    python tools/bench_kernel_args.py [--json] [--quick]
"""

from __future__ import annotations

import argparse
import gc
import json
import time
from collections.abc import Callable
from typing import Any

import numpy as np

N = 6


def _kernels() -> dict[str, Any]:
    import numba
    from numba.core import types
    from numba.experimental import structref

    jit = numba.njit(cache=False, nogil=True, error_model="numpy")

    @jit
    def sep3(a, b, out):
        for j in range(out.shape[0]):
            out[j] = a[j] + b[j]

    @jit
    def sep13(a0, a1, a2, a3, a4, a5, a6, a7, a8, a9, a10, a11, out):
        for j in range(out.shape[0]):
            out[j] = (
                a0[j] + a1[j] + a2[j] + a3[j] + a4[j] + a5[j]
                + a6[j] + a7[j] + a8[j] + a9[j] + a10[j] + a11[j]
            )  # fmt: skip

    @jit
    def block(w):  # rows 0..11 inputs, row 12 the output
        for j in range(w.shape[1]):
            s = 0.0
            for r in range(12):
                s += w[r, j]
            w[12, j] = s

    @jit
    def block2(w, iw):  # a float block and an int block
        for j in range(w.shape[1]):
            s = 0.0
            for r in range(12):
                s += w[r, j]
            w[12, j] = s + iw[0, j]

    @jit
    def tup(t, out):
        for j in range(out.shape[0]):
            s = 0.0
            for r in range(12):
                s += t[r][j]
            out[j] = s

    @jit
    def jc(h):
        for j in range(h.a12.shape[0]):
            h.a12[j] = (
                h.a0[j] + h.a1[j] + h.a2[j] + h.a3[j] + h.a4[j] + h.a5[j]
                + h.a6[j] + h.a7[j] + h.a8[j] + h.a9[j] + h.a10[j] + h.a11[j]
            )  # fmt: skip

    @structref.register
    class _SRType(types.StructRef):
        def preprocess_fields(self, fields):
            return tuple((n, types.unliteral(t)) for n, t in fields)

    class SR(structref.StructRefProxy):
        pass

    structref.define_proxy(SR, _SRType, [f"a{i}" for i in range(13)])

    @jit
    def sr(h):
        for j in range(h.a12.shape[0]):
            h.a12[j] = (
                h.a0[j] + h.a1[j] + h.a2[j] + h.a3[j] + h.a4[j] + h.a5[j]
                + h.a6[j] + h.a7[j] + h.a8[j] + h.a9[j] + h.a10[j] + h.a11[j]
            )  # fmt: skip

    @jit
    def scal(w, x, y, z, f1, f2, f3):  # one array, three floats, three bools
        for j in range(w.shape[1]):
            w[1, j] = w[0, j] * x + y * f1 + z * f2 + f3

    @jit
    def scal3(w, x, y, z):  # one array and three scalars
        w[1, 0] = w[0, 0] * x + y * z

    @jit
    def one(w):
        w[0, 0] = w[0, 0]

    return {
        "sep3": sep3,
        "sep13": sep13,
        "block": block,
        "block2": block2,
        "tup": tup,
        "jc": jc,
        "SR": SR,
        "sr": sr,
        "scal": scal,
        "scal3": scal3,
        "one": one,
    }


def _variants(k: dict[str, Any]) -> dict[str, Callable[[], None]]:
    rng = np.random.default_rng(1)
    arrs = [rng.standard_normal(N) for _ in range(13)]
    w = rng.standard_normal((13, N))
    iw = np.zeros((2, N), dtype=np.int64)
    tupl = tuple(arrs[:12])
    out = arrs[12]
    # a jitclass with the 13 arrays as members, built by its constructor
    from numba import float64
    from numba.experimental import jitclass

    spec = [(f"a{i}", float64[:]) for i in range(13)]
    src = "def __init__(self, " + ", ".join(f"a{i}" for i in range(13)) + "):\n"
    src += "".join(f"    self.a{i} = a{i}\n" for i in range(13))
    ns: dict[str, Any] = {}
    exec(src, ns)  # a fixed constructor of the benchmark's own class
    H = jitclass(spec)(type("H", (), {"__init__": ns["__init__"]}))
    h = H(*arrs)
    s = k["SR"](*arrs)
    sep3, sep13, block, block2, tup = k["sep3"], k["sep13"], k["block"], k["block2"], k["tup"]
    jc, sr, scal, scal3, one = k["jc"], k["sr"], k["scal"], k["scal3"], k["one"]
    a = arrs
    v: dict[str, Callable[[], None]] = {
        "empty Python call": lambda: None,
        "1 array (2-D)": lambda: one(w),
        "3 arrays (1-D)": lambda: sep3(a[0], a[1], out),
        "13 arrays (1-D)": lambda: sep13(
            a[0], a[1], a[2], a[3], a[4], a[5], a[6], a[7], a[8], a[9], a[10], a[11], out
        ),
        "1 2-D block (13 rows)": lambda: block(w),
        "2 blocks (float + int)": lambda: block2(w, iw),
        "tuple of 12 arrays + out": lambda: tup(tupl, out),
        "jitclass of 13 arrays": lambda: jc(h),
        "structref of 13 arrays": lambda: sr(s),
        "1 array + 3 floats": lambda: scal3(w, 1.0, 2.0, 3.0),
        "1 array + 3 bools": lambda: scal3(w, True, False, True),
        "1 array + 3 ints": lambda: scal3(w, 1, 2, 3),
        "1 array + 3 floats + 3 bools": lambda: scal(w, 1.0, 2.0, 3.0, True, False, True),
    }
    return v


def _flush(big: np.ndarray, junk: list[int]) -> None:
    big += 1.0  # 8 MiB through the caches
    d = {}
    for i in range(300):  # some interpreter work, as the exchange's Python does
        d[i] = junk[i % len(junk)] + i


def measure(blocks: int, per_block: int) -> dict[str, dict[str, float]]:
    k = _kernels()
    calls = _variants(k)
    for fn in calls.values():  # compile now
        fn()
    big = np.zeros(1 << 20)
    junk = list(range(64))
    clock = time.perf_counter_ns
    times: dict[tuple[str, bool], list[int]] = {(n, f): [] for n in calls for f in (False, True)}
    base: dict[bool, list[int]] = {False: [], True: []}
    gc.disable()
    try:
        for _ in range(blocks):
            for flush in (False, True):
                for _i in range(per_block):
                    if flush:
                        _flush(big, junk)
                    t0 = clock()
                    base[flush].append(clock() - t0)
                for name, fn in calls.items():
                    t = times[(name, flush)]
                    for _i in range(per_block):
                        if flush:
                            _flush(big, junk)
                        t0 = clock()
                        fn()
                        t.append(clock() - t0)
    finally:
        gc.enable()
    off = {f: float(np.median(base[f])) for f in (False, True)}
    return {
        name: {
            "alone": (float(np.median(times[(name, False)])) - off[False]) / 1000.0,
            "flushed": (float(np.median(times[(name, True)])) - off[True]) / 1000.0,
        }
        for name in calls
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", action="store_true", help="print the figures as JSON")
    ap.add_argument("--quick", action="store_true", help="fewer samples (a few seconds)")
    args = ap.parse_args()
    blocks, per_block = (10, 200) if args.quick else (40, 300)
    res = measure(blocks, per_block)
    if args.json:
        print(json.dumps({"median_us": res, "calls_per_variant": blocks * per_block}, indent=2))
        return
    print(f"{'call (n = 6)':32s} {'alone':>7s} {'flushed':>8s}   [µs, median]")
    for name, r in res.items():
        print(f"{name:32s} {r['alone']:7.2f} {r['flushed']:8.2f}")


if __name__ == "__main__":
    main()
