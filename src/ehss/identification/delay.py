"""The input delay of a record, estimated before any order is chosen."""

from __future__ import annotations

from typing import Any

import numpy as np

from ehss._checks import check_int
from ehss.errors import DataError
from ehss.identification.rels import check_record

__all__ = ["estimate_delay", "default_max_delay"]

#: impulse-response taps estimated beyond the largest delay tried
_TAIL = 10
#: samples of the record per estimated tap, at least
_ROWS_PER_TAP = 10
#: a tap is a response when it exceeds this many standard errors of its estimate
_SIGNIFICANT = 4.0
#: rows of the least-squares problem (the first of a longer record)
_MAX_ROWS = 100_000


def default_max_delay(n_samples: int) -> int:
    """The largest delay :func:`estimate_delay` looks for in a record of ``n_samples``:
    as many as the record has 10 samples a tap for, at most 100."""
    return max(0, min(100, n_samples // (_ROWS_PER_TAP + 1) - 1 - _TAIL))


def estimate_delay(u: Any, y: Any, *, max_delay: int | None = None) -> int | None:
    """The input delay (samples): the first lag at which ``y`` responds to ``u``.

    The impulse response h(0..L−1), L = ``max_delay`` + 11, is estimated by least
    squares as an FIR model y(k) = Σ h(j) u(k − j) + v(k) (means removed); unlike an
    ARX model, that estimate is not biased by output noise. The delay is the first lag
    whose tap exceeds 4 standard errors of its estimate (the residual variance times
    the diagonal of (ΦᵀΦ)⁻¹). A response whose first tap is small (a low-pass whose
    b0 ≈ 0) may be placed a sample late; an order search around it settles that. The
    delay can be resolved no finer than the excitation allows (about half a period of
    its highest frequency): a record far oversampled for its test signal (0.5–20 Hz at
    1 kHz) places it early, and is best decimated first, as ``ehss order`` does.

    Parameters
    ----------
    u, y : array_like, shape (n_samples,)
        Input and output, finite (the first 100 000 samples are used).
    max_delay : int, optional
        Largest delay looked for. Default :func:`default_max_delay`.

    Returns
    -------
    int or None
        None when no tap up to ``max_delay`` is significant: the record shows no
        response of ``y`` to ``u``.

    Raises
    ------
    DataError
        If the record is too short for the taps (10 samples per tap).

    Examples
    --------
    >>> import numpy as np
    >>> u = np.random.default_rng(0).standard_normal(2000)
    >>> h = np.r_[np.zeros(7), 0.5 * 0.8 ** np.arange(60)]  # a lag behind 7 samples
    >>> estimate_delay(u, np.convolve(u, h)[: u.size])
    7
    """
    u, y = check_record(u, y)
    n = u.size
    if max_delay is None:
        max_delay = default_max_delay(n)
    max_delay = check_int(max_delay, "max_delay", lo=0)
    taps = max_delay + 1 + _TAIL
    if n - taps < _ROWS_PER_TAP * taps:
        raise DataError(f"{n} samples are too few to estimate a delay up to {max_delay} "
                        f"samples (need at least {(_ROWS_PER_TAP + 1) * taps})")
    u = u - np.mean(u)
    y = y - np.mean(y)
    rows = np.arange(taps - 1, min(n, taps - 1 + _MAX_ROWS))
    phi = np.column_stack([u[rows - j] for j in range(taps)])
    h, *_ = np.linalg.lstsq(phi, y[rows], rcond=None)
    e = y[rows] - phi @ h
    noise = float(e @ e) / max(rows.size - taps, 1)
    se = np.sqrt(noise * np.diag(np.linalg.pinv(phi.T @ phi)))
    responding = np.flatnonzero(np.abs(h[: max_delay + 1]) > _SIGNIFICANT * se[: max_delay + 1])
    return int(responding[0]) if responding.size else None
