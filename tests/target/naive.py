"""Slow, obvious references for the target filter, and random compensators to test it.

The references do not share the filter's code: the cascade is scipy.signal.sosfilt, the
FIR part np.convolve, and a cross-fade is written out from its definition over whole
outputs computed from each compensator's start.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.signal

from ehss.target import Compensator


def random_section(rng: np.random.Generator, *, first_order: bool = False) -> np.ndarray:
    """A stable section with poles of radius 0.2..0.9 and a peak gain of about 1."""
    r = rng.uniform(0.2, 0.9)
    if first_order:
        a = [1.0, -r * rng.choice([-1.0, 1.0]), 0.0]
        b = [rng.standard_normal(), rng.standard_normal(), 0.0]
    else:
        theta = rng.uniform(0.0, np.pi)
        a = [1.0, -2 * r * np.cos(theta), r * r]
        b = list(rng.standard_normal(3))
    _, h = scipy.signal.freqz(b, a, worN=256)
    scale = 1.0 / max(np.max(np.abs(h)), 1e-3)
    return np.array([*(scale * np.asarray(b)), *a])


def random_compensator(rng: np.random.Generator, n_sections: int, n_taps: int, *,
                       preview: int = 0, fs_hz: float = 5000.0) -> Compensator:
    """A compensator of ``n_sections`` random stable sections and ``n_taps`` random taps."""
    sos = np.array([random_section(rng, first_order=bool(i % 3 == 2))
                    for i in range(n_sections)]).reshape(n_sections, 6)
    taps = rng.standard_normal(n_taps) / np.sqrt(n_taps)
    return Compensator(sos=sos, taps=taps, preview=preview, fs_hz=fs_hz)


def reference_filter(c: Compensator, x: np.ndarray) -> np.ndarray:
    """``c`` run over ``x`` from a zero state: sosfilt, then np.convolve."""
    v = scipy.signal.sosfilt(np.array(c.sos), x) if c.n_sections else np.asarray(x, dtype=float)
    return np.convolve(v, c.taps)[: x.size]


def reference_swaps(x: np.ndarray, initial: Compensator,
                    swaps: list[tuple[int, Compensator, int, int]]) -> np.ndarray:
    """The drive for ``x`` when each ``(t, c, k0, N)`` of ``swaps`` starts ``c`` from
    a zero state at sample ``t`` (in shadow until ``k0 >= t``) and fades it in over
    ``k0 .. k0 + N - 1`` with w = (k - k0 + 1) / N; each fade ends before the next
    swap starts."""
    y = reference_filter(initial, x)
    for t, c, k0, n in swaps:
        new = np.zeros_like(x)
        new[t:] = reference_filter(c, x[t:])
        n = max(n, 1)
        for k in range(k0, min(k0 + n, x.size)):
            w = (k - k0 + 1) / n
            y[k] = (1 - w) * y[k] + w * new[k]
        y[k0 + n:] = new[k0 + n:]
    return y


def reference_settle(c: Compensator) -> int:
    """Samples ``c`` needs from rest: its taps, then 7 time constants of the slowest
    section mode, the radius from ``np.roots`` (not the closed form the filter uses)."""
    radius = max((float(np.max(np.abs(np.roots(row[3:])))) for row in np.array(c.sos)
                  if np.any(row[4:] != 0.0)), default=0.0)
    if radius == 0.0:
        return c.n_taps
    return c.n_taps + math.ceil(7.0 / -math.log(radius))
