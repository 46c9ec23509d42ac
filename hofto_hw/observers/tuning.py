"""Observer bandwidths, measured, so that comparisons are not artefacts of gains.

A nonlinear observer (HOFTO, STA) has no transfer function; its equivalent linearisation at
a given signal amplitude is the describing function: the first-harmonic gain from x3 to its
estimate z3. :func:`first_harmonic_gain` measures it on a unit double integrator
(q'' = x3, x3 = A·sin(2π·f·t), no model error, no noise) for many frequencies at once (one
channel per frequency), and :func:`bandwidth_3db` returns the frequency where it first falls
to 1/√2. Matched linear observers then get the same -3 dB frequency f_c:
- ESO with a triple pole at -w0 (k = 3·w0, 3·w0², w0³): |H| = 1/√2 at w = w0·sqrt(2^(1/3) - 1),
  so w0 = 2π·f_c / 0.5098;
- DOB with cutoff g: |H| = 1/√2 at g, so g = 2π·f_c.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

ESO_3DB_FACTOR = float(np.sqrt(2.0 ** (1.0 / 3.0) - 1.0))  # 0.5098

#: a factory making a core with .reset(y, yd) and .step(y, a, dt) -> z3 on `channels` channels
CoreFactory = Callable[[int], object]


def first_harmonic_gain(
    make_core: CoreFactory,
    amplitude: float,
    freqs_hz: np.ndarray,
    dt: float = 1e-3,
    duration: float = 8.0,
) -> np.ndarray:
    """|Z3(f)/X3(f)| of the first harmonic, shape (len(freqs_hz),).

    The fit uses the second half of the run (sine, cosine and a constant by least squares).
    """
    freqs = np.asarray(freqs_hz, dtype=float)
    w = 2.0 * np.pi * freqs
    core = make_core(freqs.size)
    core.reset(np.zeros(freqs.size), -amplitude / w)  # q = -A/w²·sin(wt): at rest in x3
    steps = int(round(duration / dt))
    start = steps // 2
    t_fit = (np.arange(start, steps) + 1) * dt
    z3_hist = np.zeros((steps - start, freqs.size))
    zeros = np.zeros(freqs.size)
    for k in range(steps):
        t = (k + 1) * dt
        y = -amplitude / w**2 * np.sin(w * t)
        z3 = core.step(y, zeros, dt)
        if k >= start:
            z3_hist[k - start] = z3
    gains = np.zeros(freqs.size)
    for i in range(freqs.size):
        basis = np.column_stack([np.sin(w[i] * t_fit), np.cos(w[i] * t_fit), np.ones_like(t_fit)])
        coef, *_ = np.linalg.lstsq(basis, z3_hist[:, i], rcond=None)
        gains[i] = np.hypot(coef[0], coef[1]) / amplitude
    return gains


def bandwidth_3db(freqs_hz: np.ndarray, gains: np.ndarray) -> float:
    """First frequency [Hz] where ``gains`` falls below 1/√2 (log-linear interpolation).

    Raises ValueError if it never does within the sweep.
    """
    level = 1.0 / np.sqrt(2.0)
    below = np.nonzero(gains < level)[0]
    if below.size == 0 or below[0] == 0:
        raise ValueError("the -3 dB point is outside the swept frequencies")
    i = below[0]
    f0, f1 = np.log(freqs_hz[i - 1]), np.log(freqs_hz[i])
    g0, g1 = gains[i - 1], gains[i]
    return float(np.exp(f0 + (level - g0) * (f1 - f0) / (g1 - g0)))
