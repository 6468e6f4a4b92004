"""How long a compensator filter started at rest takes to forget its start.

One rule, shared by the host that schedules a compensator (:mod:`ehss.compensation`)
and the filter a target runs (:mod:`ehss.target`, and its C twin,
``ehss_comp_settle_samples``): a filter of second-order sections followed by ``n_taps``
FIR taps, started from a zero state, gives the output it would have given had it run
all along once its FIR delay line has filled (``n_taps`` samples) and its slowest
section mode has decayed by e^-7 (< 0.1 %): 7 / (−ln r) samples, r the largest pole
radius of the sections. The pole radius of z² + a1 z + a2 in closed form: √a2 for a
complex pair, (|a1| + √(a1² − 4 a2)) / 2 for real poles.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["SETTLE_TIME_CONSTANTS", "decay_samples", "pole_radius", "settle_samples"]

#: A filter started at rest has forgotten its start after this many time constants of
#: its slowest mode (e^-7 < 0.1 %).
SETTLE_TIME_CONSTANTS = 7.0


def pole_radius(a1: float, a2: float) -> float:
    """Largest |z| over the roots of z² + a1 z + a2."""
    disc = a1 * a1 - 4.0 * a2
    if disc < 0.0:
        return math.sqrt(a2)
    return 0.5 * (abs(a1) + math.sqrt(disc))


def settle_samples(sos: np.ndarray, n_taps: int = 0) -> int:
    """Samples after which a filter of sections ``sos`` (scipy's layout, a0 = 1, stable)
    and ``n_taps`` FIR taps, started at rest, has forgotten its start.

    Examples
    --------
    >>> settle_samples(np.array([[1.0, 0, 0, 1.0, -0.5, 0.0]]), n_taps=10)  # pole 0.5
    21
    """
    radius = 0.0
    for a1, a2 in np.asarray(sos, dtype=float).reshape(-1, 6)[:, 4:6]:
        radius = max(radius, pole_radius(float(a1), float(a2)))
    return int(n_taps) + decay_samples(radius)


def decay_samples(radius: float) -> int:
    """Samples in which a mode of pole radius ``radius`` (< 1) decays by
    e^-:data:`SETTLE_TIME_CONSTANTS`: 0 for none (radius 0).

    Examples
    --------
    >>> decay_samples(0.5), decay_samples(0.0)
    (11, 0)
    """
    if radius <= 0.0:
        return 0
    decay = max(-math.log(min(radius, 1.0 - 1e-12)), 1e-12)
    return int(math.ceil(SETTLE_TIME_CONSTANTS / decay))
