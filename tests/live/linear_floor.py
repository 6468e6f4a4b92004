"""The best fixed linear inverse of a rig, found in hindsight: the floor of what a fixed
linear compensator that tracks closely can reach on a record.

The drive is iterated on the whole record, ``u = W D / Ĥ + (1 - W) D`` in the frequency
domain, with ``D`` the desired output's spectrum, ``W`` the reference's band and ``Ĥ``
the H1 estimate drive → feedback of the last run (the rig's best linear approximation
at that drive). At its fixed point the error ``d - y`` is uncorrelated with the drive
at every frequency of the band, and so with the reference, which the drive is a linear
filter of: a change ``δF`` of the inverse adds ``G δF d`` to the error, uncorrelated
with what is there, and lowers it only through the distortion it changes. Where the
loop tracks its reference closely, the distortion is a function of the motion, which
any inverse that tracks as closely leaves nearly the same: what is left is the rig's
nonlinear distortion and its sensor noise at that motion. (Where the drive itself is
distorted far from the motion, as by a clipped valve, the fixed point is no optimum:
an earlier iterate can leave less.) It uses the whole record, the future included, and
the rig's own simulation run again and again: an online compensator has neither.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

import ehss

__all__ = ["fixed_linear_floor", "stretch_rms"]


def fixed_linear_floor(run: Callable[[np.ndarray], np.ndarray], desired: np.ndarray, fs: float,
                       band_hz: tuple[float, float], *, iterations: int = 3,
                       skip_s: float = 5.0) -> list[np.ndarray]:
    """The tracking errors ``desired - run(u)`` of the iterated drive, one per run (the
    first with ``u = desired``).

    Parameters
    ----------
    run : callable
        The rig: drive of shape (n_channels, n) → feedback of the same shape.
    desired : ndarray, shape (n_channels, n)
    fs : float
    band_hz : (lo, hi)
        The reference's band; the inverse acts from half its lower edge to 1.25 times
        its upper one, the drive is the reference elsewhere.
    iterations : int
        Runs after the first.
    skip_s : float
        Seconds at the record's start the H1 estimate leaves out (the loop's start-up).
    """
    n = desired.shape[1]
    f = np.fft.rfftfreq(n, 1.0 / fs)
    inside = (f > 0.5 * band_hz[0]) & (f < 1.25 * band_hz[1])
    d_spec = np.fft.rfft(desired, axis=1)
    # segments of about 8 s: 0.12 Hz apart at 1 kHz, and a few averages over 40 s
    nperseg = 1 << int(round(np.log2(8.0 * fs)))
    skip = int(skip_s * fs)
    drive = desired.copy()
    errors = []
    for it in range(iterations + 1):
        feedback = run(drive)
        errors.append(desired - feedback)
        if it == iterations:
            break
        h = np.ones_like(d_spec)
        for k in range(desired.shape[0]):
            h1 = ehss.h1_estimate(drive[k, skip:], feedback[k, skip:], fs, nperseg=nperseg)
            h[k, inside] = (np.interp(f[inside], h1.freq_hz, h1.response.real)
                            + 1j * np.interp(f[inside], h1.freq_hz, h1.response.imag))
        drive = np.fft.irfft(np.where(inside, d_spec / h, d_spec), n, axis=1)
    return errors


def stretch_rms(error: Any, fs: float, t0: float, t1: float) -> np.ndarray:
    """RMS of ``error`` (n_channels, n) over [t0, t1) s, per channel."""
    e = np.asarray(error)[:, int(round(t0 * fs)):int(round(t1 * fs))]
    return np.sqrt(np.mean(e ** 2, axis=1))
