"""The input delay of a record, estimated before any order is chosen.

:func:`estimate_delay` places the first lag at which the output responds to the input;
:func:`scan_delays` checks that the record supports that estimate (the same delay from
each half of the record as from the whole) and otherwise proposes a range of small
delays and orders that covers the response's rise, for an order search to settle.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.signal
from threadpoolctl import threadpool_limits

from ehss._checks import as_record, check_int
from ehss.errors import DataError

__all__ = ["estimate_delay", "default_max_delay", "DelayScan", "scan_delays"]

#: impulse-response taps estimated beyond the largest delay tried
_TAIL = 10
#: past outputs in the regression: they carry the response beyond the last tap, which
#: would otherwise count as noise (a slow loop's memory is far longer than the taps)
_AR_TAIL = 8
#: samples of the record per estimated parameter, at least
_ROWS_PER_TAP = 10
#: a tap is a response when it exceeds this many standard errors of its estimate (a
#: false alarm at one tap of pure noise has a probability of 6e-5; over 100 taps, 0.6 %)
_SIGNIFICANT = 4.0
#: rows of the least-squares problem (the first of a longer record)
_MAX_ROWS = 100_000
#: the most delays a fallback proposes, and the highest nb it proposes (grid size: every
#: delay is tried with every nb)
_FALLBACK_DELAYS = 4
_FALLBACK_MAX_NB = 6
#: nb proposed when the delay is supported (the order search's usual low orders)
_DEFAULT_MAX_NB = 3


def default_max_delay(n_samples: int) -> int:
    """The largest delay :func:`estimate_delay` looks for in a record of ``n_samples``:
    as many as the record has 10 samples a parameter for, at most 100."""
    return max(0, min(100, n_samples // (_ROWS_PER_TAP + 1) - 1 - _TAIL - _AR_TAIL))


def _taps(u: np.ndarray, y: np.ndarray, n_taps: int) -> tuple[np.ndarray, np.ndarray,
                                                                np.ndarray]:
    """Least-squares y(k) = Σ_j h(j) u(k − j) − Σ_i a(i) y(k − i) + v(k): the taps h,
    their standard errors and the past-output coefficients a (means removed)."""
    u = u - np.mean(u)
    y = y - np.mean(y)
    k0 = max(n_taps - 1, _AR_TAIL)
    rows = np.arange(k0, min(y.size, k0 + _MAX_ROWS))
    phi = np.column_stack([u[rows - j] for j in range(n_taps)]
                          + [-y[rows - i] for i in range(1, _AR_TAIL + 1)])
    # one BLAS thread: on a machine whose cores are busy, a multi-threaded LAPACK
    # spends more time waiting for its threads than solving (BENCHMARKS.md, Order search)
    with threadpool_limits(limits=1, user_api="blas"):
        theta, *_ = np.linalg.lstsq(phi, y[rows], rcond=None)
        e = y[rows] - phi @ theta
        noise = float(e @ e) / max(rows.size - phi.shape[1], 1)
        # a floor at rounding level: a noise-free record's taps are exact, not
        # significant wherever rounding leaves them a little off zero
        noise = max(noise, 1e-20 * float(y @ y) / y.size)
        se = np.sqrt(noise * np.diag(np.linalg.pinv(phi.T @ phi)))
    return theta[:n_taps], se[:n_taps], theta[n_taps:]


def _check_length(n: int, max_delay: int) -> int:
    params = max_delay + 1 + _TAIL + _AR_TAIL
    if n - params < _ROWS_PER_TAP * params:
        raise DataError(f"{n} samples are too few to estimate a delay up to {max_delay} "
                        f"samples (need at least {(_ROWS_PER_TAP + 1) * params})")
    return max_delay + 1 + _TAIL


def estimate_delay(u: Any, y: Any, *, max_delay: int | None = None) -> int | None:
    """The input delay (samples): the first lag at which ``y`` responds to ``u``.

    The impulse response h(0..L−1), L = ``max_delay`` + 11, is estimated by least
    squares together with 8 past outputs, y(k) = Σ h(j) u(k − j) − Σ a(i) y(k − i) +
    v(k) (means removed): the past outputs carry the response beyond the last tap, so
    a slow loop's long memory is not taken for noise. The delay is the first lag whose
    tap exceeds 4 standard errors of its estimate (the residual variance times the
    diagonal of (ΦᵀΦ)⁻¹). A response whose first tap is small (a low-pass whose
    b0 ≈ 0) may be placed a sample late; an order search around it settles that. The
    delay can be resolved no finer than the excitation allows (about half a period of
    its highest frequency): a record far oversampled for its test signal places it
    early or anywhere; :func:`scan_delays` checks whether the record supports it.

    Parameters
    ----------
    u, y : array_like, shape (n_samples,)
        Input and output, finite (the first 100 000 samples are used).
    max_delay : int, optional
        Largest delay looked for. Default :func:`default_max_delay`.

    Returns
    -------
    int or None
        None when no tap up to ``max_delay`` is significant.

    Raises
    ------
    DataError
        If the record is too short for the taps (10 samples per parameter).

    Examples
    --------
    >>> import numpy as np
    >>> u = np.random.default_rng(0).standard_normal(2000)
    >>> h = np.r_[np.zeros(7), 0.5 * 0.8 ** np.arange(60)]  # a lag behind 7 samples
    >>> estimate_delay(u, np.convolve(u, h)[: u.size])
    7
    """
    u, y = as_record(u, y)
    if max_delay is None:
        max_delay = default_max_delay(u.size)
    max_delay = check_int(max_delay, "max_delay", lo=0)
    n_taps = _check_length(u.size, max_delay)
    h, se, _ = _taps(u, y, n_taps)
    with np.errstate(invalid="ignore", divide="ignore"):
        z = np.abs(h[: max_delay + 1]) / se[: max_delay + 1]
    responding = np.flatnonzero(z > _SIGNIFICANT)
    return int(responding[0]) if responding.size else None


@dataclass(frozen=True, kw_only=True)
class DelayScan:
    """What a record says about its input delay (:func:`scan_delays`).

    Attributes
    ----------
    delay : int or None
        The delay the record supports (samples), or None when it supports none.
    whole, halves : int or None, (int or None, int or None)
        :func:`estimate_delay` on the whole record and on each half.
    delays : tuple of int
        Candidate delays for an order search: ``delay − 1`` and ``delay`` when it is
        supported (the estimate may be a sample late); otherwise up to 4 delays spread
        from 0 to the sample where the response reaches 10 % of its peak.
    max_nb : int
        Highest nb to try with them: 3, or when the delay is not supported, enough taps
        to span the rise from 10 % to 50 % of the peak (3 to 6).
    rise : (int, int) or None
        Samples at which the estimated step response reaches 10 % and 50 % of its peak
        (None when the estimate is unstable or does not rise).
    max_delay : int
        The longest delay looked for.
    """

    delay: int | None
    whole: int | None
    halves: tuple[int | None, int | None]
    delays: tuple[int, ...]
    max_nb: int
    rise: tuple[int, int] | None
    max_delay: int

    @property
    def supported(self) -> bool:
        """The record supports a delay estimate."""
        return self.delay is not None


def scan_delays(u: Any, y: Any, *, max_delay: int | None = None) -> DelayScan:
    """Estimate the delay, check that the record supports it, and propose candidates.

    The delay is estimated (:func:`estimate_delay`) on the whole record and on each of
    its halves. It is supported when all three find one and the halves agree with the
    whole within a sample: a record that cannot resolve its delay (an input band-limited
    far below the Nyquist frequency, where the taps are ill-determined; a loop slower
    than the taps can follow) gives estimates that scatter or none. When it is not
    supported, the candidates cover the response's rise instead: the step response of
    the same regression (taps and past outputs) gives the samples ``t10`` and ``t50``
    at which it reaches 10 % and 50 % of its peak; the dead time ends no later than
    ``t10``, so up to 4 delays spread over [0, t10] are proposed, with nb up to
    ``t50 − t10`` (clipped to 3..6) so that a candidate's taps can span the rise.

    Parameters
    ----------
    u, y : array_like, shape (n_samples,)
    max_delay : int, optional
        Largest delay looked for; default :func:`default_max_delay` of half the record
        (of the whole when a half is too short to look for any delay: then the estimate
        cannot be checked, and is not taken as supported).

    Returns
    -------
    DelayScan

    Raises
    ------
    DataError
        If the record is too short for the taps (:func:`estimate_delay`).
    """
    u, y = as_record(u, y)
    half = u.size // 2
    # halves too short to look for even delay 0: the whole record alone, never supported
    split = default_max_delay(half) > 0
    if max_delay is None:
        max_delay = default_max_delay(half if split else u.size)
    max_delay = check_int(max_delay, "max_delay", lo=0)
    _check_length(half if split else u.size, max_delay)
    whole = estimate_delay(u, y, max_delay=max_delay)
    halves: tuple[int | None, int | None] = (None, None)
    if split:
        halves = (estimate_delay(u[:half], y[:half], max_delay=max_delay),
                  estimate_delay(u[half:], y[half:], max_delay=max_delay))
    agree = whole is not None and all(h is not None and abs(h - whole) <= 1 for h in halves)
    if agree:
        assert whole is not None
        return DelayScan(delay=whole, whole=whole, halves=halves,
                         delays=tuple(sorted({max(whole - 1, 0), whole})),
                         max_nb=_DEFAULT_MAX_NB, rise=None, max_delay=max_delay)
    rise = _rise(u, y, max_delay + 1 + _TAIL)
    delays: tuple[int, ...]
    if rise is None:
        delays, max_nb = (0, 1), _DEFAULT_MAX_NB
    else:
        t10, t50 = rise
        delays = tuple(sorted({int(round(v)) for v in np.linspace(0, min(t10, max_delay),
                                                                  _FALLBACK_DELAYS)}))
        max_nb = int(min(max(t50 - t10, _DEFAULT_MAX_NB), _FALLBACK_MAX_NB))
    return DelayScan(delay=None, whole=whole, halves=halves, delays=delays, max_nb=max_nb,
                     rise=rise, max_delay=max_delay)


def _rise(u: np.ndarray, y: np.ndarray, n_taps: int) -> tuple[int, int] | None:
    """Samples at which the regression's step response reaches 10 % and 50 % of its
    peak over 20 times the taps; None if its past-output part is unstable."""
    h, _, a = _taps(u, y, n_taps)
    den = np.r_[1.0, a]
    if np.max(np.abs(np.roots(den))) >= 1.0:
        return None
    step = scipy.signal.lfilter(h, den, np.ones(20 * n_taps))
    size = np.abs(step)
    peak = float(np.max(size))
    if not (np.isfinite(peak) and peak > 0):
        return None
    return int(np.argmax(size >= 0.1 * peak)), int(np.argmax(size >= 0.5 * peak))
