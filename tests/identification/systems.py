"""Known test systems and excitations for the identification tests (built on demand)."""

from __future__ import annotations

import numpy as np
from scipy.signal import lfilter

FS_HZ = 1000.0
DT_S = 1.0 / FS_HZ


def resonance_poles(freq_hz, zeta, fs=FS_HZ):
    """Discretised (z = e^{s dt}) pole pair of a continuous resonance."""
    w = 2 * np.pi * freq_hz
    s = -zeta * w + 1j * w * np.sqrt(1 - zeta**2)
    z = np.exp(s / fs)
    return [z, np.conj(z)]


#: (poles spec, B zeros, C coefficients) of stable test systems of orders 2, 4, 6
SYSTEMS = {
    2: ([(20.0, 0.3)], [0.5], [1.0, -0.5]),
    4: ([(10.0, 0.2), (45.0, 0.3)], [-0.5, 0.6], [1.0, -0.6, 0.2]),
    6: ([(5.0, 0.3), (30.0, 0.2), (80.0, 0.3)], [-0.6, 0.4, 0.7], [1.0, -0.3, 0.1]),
}


def system(order):
    """(a, b, c) with unit DC gain; b multiplies u(k−1−i) (delay 1)."""
    spec, zeros, c = SYSTEMS[order]
    poles = [p for f, z in spec for p in resonance_poles(f, z)]
    a = np.real(np.poly(poles))
    b = np.real(np.poly(zeros))
    b = b * a.sum() / b.sum()
    return a, b, np.array(c, dtype=float)


def band_limited(rng, n, f_lo=2.0, f_hi=100.0, fs=FS_HZ):
    """Gaussian noise with its spectrum masked to [f_lo, f_hi] (FFT mask), unit RMS."""
    x = rng.standard_normal(n)
    spec = np.fft.rfft(x)
    f = np.fft.rfftfreq(n, 1.0 / fs)
    spec[(f < f_lo) | (f > f_hi)] = 0.0
    x = np.fft.irfft(spec, n)
    return x / np.sqrt(np.mean(x * x))


def armax_data(rng, a, b, c, n, snr_db=None, delay=1, u=None):
    """Simulate A y = q^-d B u + C ξ; ξ scaled for the given SNR (None: noise free)."""
    if u is None:
        u = band_limited(rng, n)
    bd = np.concatenate([np.zeros(delay), b])
    y0 = lfilter(bd, a, u)
    if snr_db is None:
        return u, y0, 0.0
    v = lfilter(c, a, rng.standard_normal(n))
    scale = np.sqrt(np.var(y0) / np.var(v) / 10 ** (snr_db / 10))
    return u, y0 + scale * v, scale**2


def kernel_settings(na, nb, nc, delay, lam, alpha, alpha_c, trace_max, c_radius, method,
                    enabled=True):
    """The compiled RELS loop's settings, through the checked settings object."""
    from ehss.identification import RelsSettings

    s = RelsSettings(na=na, nb=nb, nc=nc, delay=delay, forgetting=lam, p0=alpha,
                     p0_c=alpha_c, trace_bound=trace_max, c_radius=c_radius, method=method)
    return s.kernel(enabled=enabled)
