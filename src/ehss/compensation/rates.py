"""A model identified at a decimated rate, applied to a reference at the record's rate.

The identification workflow decimates an oversampled record (:func:`ehss.workflow.prepare`)
and returns a model at ``fs / q``: at the record's own rate a loop sampled at hundreds of
times its bandwidth has its dynamics squeezed next to ``z = 1`` and sampling zeros far
outside the unit circle, which makes both the estimate and its inverse ill-conditioned.
The rig, however, plays and records at ``fs``. The inverse therefore runs at the model's
rate and the rig's signals cross over by band-limited resampling:

1. the reference is brought to ``fs / q`` by a polyphase anti-aliasing filter
   (:func:`scipy.signal.resample_poly`, linear phase with its delay removed, so the
   resampled reference is not shifted in time);
2. the inverse acts there (inside the model's band, which lies below ``fs / (2 q)``);
3. the drive comes back to ``fs`` by the same polyphase interpolation.

Both use one low-pass FIR at the model's Nyquist frequency, ``fs / (2 q)`` (a Kaiser
window, β = 10, over ±32 model samples): a round trip reproduces a signal below 0.85 of
that frequency to about 1e-5 of its amplitude (0.1 % with scipy's default filter, ±10
samples and β = 5) and removes everything above it, where the model knows nothing.
Before its start and after its end a signal is taken as held at its first and last
values (as
:meth:`~ehss.compensation.inverse_model.InverseModel.apply` does).
"""

from __future__ import annotations

import math

import numpy as np
import scipy.signal

from ehss.errors import DataError

__all__ = ["RATE_RTOL", "rate_factor", "to_model_rate", "to_record_rate"]

#: Relative mismatch allowed between ``fs · dt`` and an integer.
RATE_RTOL = 1e-6

#: Half-length of the resampling filter, in samples at the model's rate, and its Kaiser β.
_HALF_LENGTH = 32
_KAISER_BETA = 10.0


def _lowpass(q: int) -> np.ndarray:
    """The polyphase filter at ``1/q`` of the record's Nyquist frequency (unit DC gain)."""
    return scipy.signal.firwin(2 * _HALF_LENGTH * q + 1, 1.0 / q,
                               window=("kaiser", _KAISER_BETA))


def rate_factor(fs: float, dt: float) -> int:
    """How many record samples make one model sample: ``q = fs · dt``, an integer ≥ 1.

    Parameters
    ----------
    fs : float
        Sample rate of the reference or record, Hz.
    dt : float
        The model's sample period, s.

    Returns
    -------
    int

    Raises
    ------
    DataError
        If the model is faster than the record, or ``fs · dt`` is not an integer: the
        record cannot be brought to the model's rate by decimation.

    Examples
    --------
    >>> rate_factor(4096.0, 17 / 4096.0)
    17
    """
    ratio = float(fs) * float(dt)
    q = round(ratio)
    if q < 1 or not math.isclose(ratio, q, rel_tol=RATE_RTOL):
        raise DataError(
            f"the reference is sampled at {fs:g} Hz but the model at {1.0 / dt:g} Hz "
            f"(dt={dt:g} s): a model can be applied at its own rate or at an integer "
            "multiple of it; resample the reference or identify at its rate")
    return int(q)


def to_model_rate(x: np.ndarray, q: int) -> np.ndarray:
    """``x`` (at the record's rate) at ``1/q`` of it, anti-alias filtered.

    The result has ``ceil(len(x) / q)`` samples; sample ``j`` is at the time of
    ``x[j q]``.
    """
    if q == 1:
        return np.asarray(x, dtype=float)
    return scipy.signal.resample_poly(np.asarray(x, dtype=float), 1, q, window=_lowpass(q),
                                      padtype="edge")


def to_record_rate(x: np.ndarray, q: int, n: int) -> np.ndarray:
    """``x`` (at the model's rate) interpolated to ``q`` times its rate, ``n`` samples.

    Inverse of :func:`to_model_rate` for signals inside the model's band:
    ``to_record_rate(to_model_rate(x, q), q, len(x))`` is ``x`` low-passed below the
    model's Nyquist frequency.
    """
    if q == 1:
        return np.asarray(x, dtype=float)[:n]
    y = scipy.signal.resample_poly(np.asarray(x, dtype=float), q, 1, window=_lowpass(q),
                                   padtype="edge")
    return np.ascontiguousarray(y[:n])
