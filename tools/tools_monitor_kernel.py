"""A compiled prototype of safety.collision.CollisionMonitor.update, for tools/bench_tick.py.

Benchmark only: it measures what a lean monitor would cost. The monitor itself
(safety/collision.py) is being reworked on another branch and is not changed here; the
benchmark checks this prototype against it tick by tick.

State st (9, n): accel, moving, reversal, qd_prev, above_time, below_time, joints (0/1),
threshold, ratio. par (4, n): base, kv, ka, kr. scal: v_rev, tau_a, moving_time,
reversal_time, release_ratio, trip_after, release_after. started (1,): 0 until the first
finite velocity is seen.
"""

from __future__ import annotations

import math

from numba import njit


@njit(cache=True, nogil=True, error_model="numpy")
def monitor_update(st, par, scal, started, tau, qd, dt):
    n = qd.shape[0]
    v_rev, tau_a, t_mov, t_rev, rel, trip, release = (
        scal[0],
        scal[1],
        scal[2],
        scal[3],
        scal[4],
        scal[5],
        scal[6],
    )
    if started[0] == 0.0:
        for j in range(n):
            st[3, j] = qd[j] if math.isfinite(qd[j]) else 0.0
        started[0] = 1.0
    alpha = dt / (tau_a + dt)
    inv_dt = 1.0 / dt
    dec_mov = math.exp(-dt / t_mov)
    dec_rev = math.exp(-dt / t_rev)
    inv_vrev = 1.0 / v_rev
    detected = False
    for j in range(n):
        v = qd[j]
        if math.isfinite(v):
            a = ((v - st[3, j]) * inv_dt - st[0, j]) * alpha
            st[0, j] = st[0, j] + a
            st[3, j] = v
            m = st[1, j] * dec_mov
            st[1, j] = max(m, 1.0 if abs(v) > v_rev else 0.0)
            x = v * inv_vrev
            r = math.exp(-(x * x)) * st[1, j]
            st[2, j] = max(st[2, j] * dec_rev, r)
        else:
            v = st[3, j]
        thr = abs(v) * par[1, j] + par[0, j]
        thr = thr + abs(st[0, j]) * par[2, j]
        thr = thr + st[2, j] * par[3, j]
        st[7, j] = thr
        t = tau[j]
        if math.isfinite(t):
            ratio = abs(t) / thr
            st[8, j] = ratio
            st[4, j] = (st[4, j] + dt) * (1.0 if ratio > 1.0 else 0.0)
            st[5, j] = (st[5, j] + dt) * (1.0 if ratio < rel else 0.0)
        else:
            st[8, j] = 0.0
        joint = st[6, j] != 0.0 or st[4, j] >= trip
        if st[5, j] >= release:
            joint = False
        st[6, j] = 1.0 if joint else 0.0
        detected = detected or joint
    return detected
