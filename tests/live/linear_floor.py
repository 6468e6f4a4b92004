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

__all__ = ["fixed_linear_floor", "stretch_rms", "stretch_refit_rms"]


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


def stretch_refit_rms(error: Any, reference: Any, fs: float, t0: float, t1: float, *,
                      taps_s: float = 0.064) -> np.ndarray:
    """RMS over [t0, t1) s of what is left of ``error`` (n_channels, n) once a linear
    filter of ``reference`` (same shape), fitted by least squares on that stretch alone,
    is taken from it: per channel.

    The filter has taps from ``-taps_s`` to ``+taps_s`` (the future of the reference
    too, as in preview mode). To first order this is what a linear inverse changed for
    that stretch alone could take from the error, knowing the error beforehand: a bound
    no online compensator, even one that changes every 2 s, can pass. It is optimistic:
    its ``2 K + 1`` coefficients take about ``(2 K + 1) / N`` of an uncorrelated error's
    power on ``N`` samples by chance. The reference is taken as zero outside the record
    (a faded one is).
    """
    e = np.asarray(error)
    i0, i1, lag = int(round(t0 * fs)), int(round(t1 * fs)), int(round(taps_s * fs))
    padded = np.pad(np.asarray(reference), ((0, 0), (lag, lag)))  # r[t] is padded[t + lag]
    out = np.empty(e.shape[0])
    for k in range(e.shape[0]):
        # column j + lag holds r[t - j] for t in the stretch, j = -lag ... lag
        lagged = np.column_stack([padded[k, i0 - j + lag:i1 - j + lag]
                                  for j in range(-lag, lag + 1)])
        coef, *_ = np.linalg.lstsq(lagged, e[k, i0:i1], rcond=None)
        out[k] = np.sqrt(np.mean((e[k, i0:i1] - lagged @ coef) ** 2))
    return out
