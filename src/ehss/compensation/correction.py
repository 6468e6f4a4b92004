"""Correcting the running compensator after a change of the rig, and comparing two.

After a change of the rig, before a full model of the new loop can be trusted, the
running compensator can be *corrected* (preview mode): :func:`fit_correction` fits a
short non-causal FIR ``K`` with ``L K ≈ 1`` to the data since the change (``L`` the
loop as compensated now), :func:`fold_correction` refits the FIR part to ``C K``, and
:meth:`ehss.compensation.adaptive.AdaptiveCompensator.assess_correction` guards it
(checked on fresh data against :data:`CORRECTION_MAX_RATIO`, its gain and phase bounded
by :data:`CORRECTION_GAIN` and :data:`CORRECTION_PHASE_DEG`, the drive checks).
:func:`compare_compensators` weighs the tracking error a new compensator would have left
on recorded data against the running one's.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.signal

from ehss._checks import check_int
from ehss.compensation.compensator_design import CompensatorDesign, _realise, _sos_response
from ehss.errors import DataError, ParameterError

__all__ = [
    "CORRECTION_MAX_RATIO",
    "CORRECTION_GAIN",
    "CORRECTION_PHASE_DEG",
    "Correction",
    "fit_correction",
    "fold_correction",
    "ErrorComparison",
    "compare_compensators",
]

#: A correction must leave at most this share of the tracking error on the samples it
#: was not fitted to: the changes it is for raise the error 4–9× (README), while noise
#: as large as the reference in the band (a burst of sensor noise) fitted the same way
#: leaves 1/√2 of it.
CORRECTION_MAX_RATIO = 0.5
#: Bounds of a correction's gain and phase over the band. ``|1 - L| = 1``, a loop whose
#: error is as large as its reference, lies at a phase of 60° for a gain of 1 and at a
#: gain of 1/2 or 2 in phase: a correction beyond ±60° or outside [1/3, 3] would follow a
#: loop that no longer tracks (a feedback flipped gives ``K = -1``, a stuck sensor an
#: unbounded one), not a change of one that does.
CORRECTION_GAIN = (1.0 / 3.0, 3.0)
CORRECTION_PHASE_DEG = 60.0


@dataclass(frozen=True, kw_only=True)
class Correction:
    """A short non-causal FIR ``K`` that corrects the running compensator after a change.

    With the running compensator ``C`` the loop from the desired reference ``r`` to the
    feedback ``y`` is ``L = G C``; when the rig changes, ``L`` moves away from 1. The
    correction is the least-squares ``K`` with ``r ≈ K y``,

    .. math:: r[k] \\approx \\sum_{j=-m}^{m} \\kappa_j\\, y[k + j],

    so that ``L K ≈ 1`` in the band, and the compensator ``C K`` takes the loop back
    (:func:`fold_correction`). Five taps (``m = 2``) span a gain, a lead and a second
    derivative, as the adaptive time-series compensator of Chae et al. (2013) does.

    Attributes
    ----------
    taps : ndarray, shape (2 m + 1,)
        ``κ_{-m} .. κ_m``.
    fs_hz : float
    band_hz : (float, float)
    n_fit, n_check : int
        Samples it was fitted on, and the newer ones it was checked on.
    check_ratio : float
        RMS of the band-limited ``r − K y`` over that of ``r − y`` on the check samples
        (of ``K_then r − K y`` over ``K_then r − K_then y`` under an earlier correction
        ``K_then``): the tracking error it leaves of the one that runs, on data it was
        not fitted to.
    check_residual : float
        RMS of that error over the reference's (``r`` or ``K_then r``) there.
    refines : bool
        Whether it replaces an earlier correction (fitted on data under one).
    gain_range : (float, float)
        Least and largest ``|K|`` over the band.
    max_phase_deg : float
        Largest ``|arg K|`` over the band.
    """

    taps: np.ndarray = field(repr=False)
    fs_hz: float
    band_hz: tuple[float, float]
    n_fit: int
    n_check: int
    check_ratio: float
    check_residual: float
    refines: bool
    gain_range: tuple[float, float]
    max_phase_deg: float

    def frequency_response(self, freq_hz: Any) -> np.ndarray:
        """``K(e^{jω}) = Σ κ_j e^{jωj}`` at ``freq_hz``."""
        m = (self.taps.size - 1) // 2
        w = 2.0 * np.pi * np.asarray(freq_hz, dtype=float) / self.fs_hz
        return np.exp(1j * np.outer(w, np.arange(-m, m + 1))) @ self.taps

    def figures(self) -> dict[str, Any]:
        """JSON-ready: its taps and what it was judged on."""
        return {"correction_taps": [float(v) for v in self.taps], "n_fit": self.n_fit,
                "check_ratio": self.check_ratio, "check_residual": self.check_residual,
                "refines": self.refines, "gain_range": list(self.gain_range),
                "max_phase_deg": self.max_phase_deg}


def _band_limited(x: np.ndarray, fs_hz: float, band: tuple[float, float]) -> np.ndarray:
    """``x`` through a zero-phase 4th-order Butterworth low-pass at the band's upper edge,
    its mean removed: the same filter on ``r`` and ``y`` keeps ``r ≈ K y``, and noise
    above the band does not enter the fit."""
    sos = scipy.signal.butter(4, band[1], fs=fs_hz, output="sos")
    return scipy.signal.sosfiltfilt(sos, x - np.mean(x))


def fit_correction(desired: Any, feedback: Any, *, fs_hz: float, band_hz: tuple[float, float],
                   spans: Any, n_check: int, half_span: int = 2,
                   base: CompensatorDesign | None = None) -> Correction:
    """The correction ``K`` of a record's spans since a change.

    Parameters
    ----------
    desired, feedback : array_like, shape (n,)
        ``r`` and ``y`` (older samples may precede the change: only the rows of
        ``spans`` enter the fit, the rest only feed the band limit's filter).
    fs_hz : float
    band_hz : (lo, hi)
    spans : sequence of (start, stop, then)
        Index ranges of the record, oldest first, each run by one compensator: ``base``,
        the one ``K`` corrects (``then`` None), or ``base`` corrected by the taps
        ``then`` of an earlier correction, or another compensator ``then`` (a
        :class:`CompensatorDesign`), whose rows then ask ``K y`` to give
        ``K_then r`` or ``(C_then / C_base) r`` (so that the rows of every span fit the
        same ``K``, the whole correction of ``base``). The last span is run by ``base``
        or a correction of it.
    n_check : int
        The newest rows (of the last span) ``K`` is checked on, not fitted to
        (:attr:`Correction.check_ratio`); the samples of the last period of the band's
        upper edge are left out (the zero-phase filter's end is not settled there).
    half_span : int
        ``m``: the taps run from ``-m`` to ``m``.
    base : CompensatorDesign, optional
        Needed when a span was run by another compensator.

    Returns
    -------
    Correction

    Raises
    ------
    DataError
        Too few rows for the taps, or a feedback that does not vary.
    """
    r = np.asarray(desired, dtype=float)
    y = np.asarray(feedback, dtype=float)
    m = check_int(half_span, "half_span", lo=0)
    edge = int(math.ceil(fs_hz / band_hz[1]))
    rf = _band_limited(r, fs_hz, band_hz)
    yf = _band_limited(y, fs_hz, band_hz)
    shifts = range(-m, m + 1)
    identity = np.zeros(2 * m + 1)
    identity[m] = 1.0
    parts: list[tuple[np.ndarray, np.ndarray]] = []
    wants: list[np.ndarray] = []
    for start, stop, then in spans:
        rows = np.arange(max(int(start), m), min(int(stop), r.size - max(edge, m)))
        if not rows.size:
            continue
        if isinstance(then, CompensatorDesign):
            if base is None:
                raise ParameterError("a span run by another compensator needs the base")
            # (C_then / C_base) r, over the band
            wants.append(_through(rf, then, base)[rows])
            k_then = identity
        else:
            k_then = identity if then is None else np.asarray(then, dtype=float)
            # r, or r through the correction that ran then
            wants.append(np.column_stack([rf[rows + j] for j in shifts]) @ k_then)
        parts.append((rows, k_then))
    if not parts:
        raise DataError("no samples to fit a correction on")
    ymat = np.vstack([np.column_stack([yf[rows + j] for j in shifts]) for rows, _ in parts])
    want = np.concatenate(wants)
    n_fit = want.size - int(n_check)
    if n_fit < 4 * (2 * m + 1) or n_check < 1:
        raise DataError(f"{n_fit} samples to fit {2 * m + 1} taps: too few")
    kappa, *_ = np.linalg.lstsq(ymat[:n_fit], want[:n_fit], rcond=None)
    if not np.all(np.isfinite(kappa)) or not np.any(ymat[:n_fit]):
        raise DataError("the feedback does not vary: no correction can be fitted")
    miss = want[n_fit:] - ymat[n_fit:] @ kappa
    was = want[n_fit:] - ymat[n_fit:] @ parts[-1][1]
    level = float(np.linalg.norm(want[n_fit:]))
    # (a loop without error leaves nothing to correct: measured against rounding then)
    ratio = float(np.linalg.norm(miss) / max(float(np.linalg.norm(was)), 1e-12 * level,
                                             1e-300))
    corr = Correction(taps=kappa, fs_hz=float(fs_hz), band_hz=band_hz, n_fit=n_fit,
                      n_check=int(n_check), check_ratio=ratio,
                      check_residual=float(np.linalg.norm(miss) / max(level, 1e-300)),
                      refines=any(isinstance(t, np.ndarray) for _, _, t in spans),
                      gain_range=(0.0, 0.0), max_phase_deg=0.0)
    k = corr.frequency_response(np.linspace(band_hz[0], band_hz[1], 64))
    return dataclasses.replace(corr, gain_range=(float(np.min(np.abs(k))),
                                                 float(np.max(np.abs(k)))),
                               max_phase_deg=float(np.max(np.abs(np.degrees(np.angle(k))))))


def _through(x: np.ndarray, then: CompensatorDesign, base: CompensatorDesign) -> np.ndarray:
    """``x`` (band-limited) through ``C_then / C_base``, by FFT over the record padded to
    twice its length (the rows it is taken at lie away from its ends)."""
    n_fft = 1 << int(math.ceil(math.log2(max(2 * x.size, then.taps.size, base.taps.size))))
    ratio = _on_grid(then, n_fft) / _on_grid(base, n_fft)
    return np.fft.irfft(np.fft.rfft(x, n_fft) * ratio, n_fft)[:x.size]


def _on_grid(design: CompensatorDesign, n_fft: int) -> np.ndarray:
    """:meth:`CompensatorDesign.frequency_response` at the ``n_fft // 2 + 1`` frequencies
    of a real FFT of ``n_fft`` points, the FIR's part by that FFT (O(n log n) instead
    of a sum over the taps at each frequency)."""
    w = 2.0 * np.pi * np.arange(n_fft // 2 + 1) / n_fft
    fir = np.fft.rfft(design.taps, n_fft)
    return np.exp(1j * w * design.preview) * _sos_response(design.sos, w) * fir


@dataclass(frozen=True)
class ErrorComparison:
    """Tracking error a new compensator would have left on recorded rows, against the
    running one's (:func:`compare_compensators`).

    Attributes
    ----------
    ratio : float
        RMS error of the new one over the running one's (band-limited; NaN: no rows).
    standard_error : float
        The ratio's standard error, from its spread over stretches of ``chunk``
        samples taken as independent (inf: fewer than two stretches). Errors that lie
        near the band's lower edge stay correlated over longer stretches: there it
        understates the ratio's scatter from one reference to another (1.5–6× over
        40 references of 1.5 s at 0.5–20 Hz, stretches of 0.1 s).
    rows : int
    """

    ratio: float
    standard_error: float
    rows: int


def _ratio_spread(e_new: np.ndarray, e_run: np.ndarray, chunk: int) -> tuple[float, float]:
    """sqrt(Σ e_new² / Σ e_run²) and its standard error by the delta method over
    stretches of ``chunk`` rows (each stretch's sums a paired sample)."""
    q = float(np.sum(e_new ** 2) / max(float(np.sum(e_run ** 2)), 1e-300))
    n = e_new.size // max(1, chunk)
    if n < 2:
        return math.sqrt(q), math.inf
    a = np.array([np.sum(p ** 2) for p in np.array_split(e_new, n)])
    b = np.array([np.sum(p ** 2) for p in np.array_split(e_run, n)])
    se_q = math.sqrt(float(np.sum((a - q * b) ** 2)) / (n * (n - 1))) / max(float(b.mean()),
                                                                         1e-300)
    return math.sqrt(q), se_q / (2.0 * math.sqrt(max(q, 1e-300)))


def compare_compensators(new: CompensatorDesign, running: CompensatorDesign, desired: Any,
                         feedback: Any, spans: Any, *, chunk: int) -> ErrorComparison:
    """The tracking error ``new`` would have left over ``spans`` of a record, against
    the error ``running`` left or would have left there (both band-limited).

    ``spans``: ``(start, stop, then)`` index ranges, each run by one compensator
    (``then``; None: ``running``). Where ``then`` ran, the feedback ``y = G C_then r``
    would have been ``(C / C_then) y`` under a compensator ``C``: the running one's
    own rows are taken as they are, the others' predicted so, and ``new``'s everywhere.
    The newest ``new.preview`` samples (and a period of the band's upper edge) are left
    out: the ratio looks that far ahead in ``y``, which is not known there.
    """
    band, fs = running.band_hz, running.fs_hz
    r = _band_limited(np.asarray(desired, dtype=float), fs, band)
    y = _band_limited(np.asarray(feedback, dtype=float), fs, band)
    end = r.size - max(new.preview, int(math.ceil(fs / band[1])))
    e_new: list[np.ndarray] = []
    e_run: list[np.ndarray] = []
    for start, stop, then in spans:
        rows = slice(int(start), min(int(stop), end))
        if rows.stop - rows.start < 1:
            continue
        then = running if then is None else then
        y_run = y if then is running else _through(y, running, then)
        e_run.append(r[rows] - y_run[rows])
        e_new.append(r[rows] - _through(y, new, then)[rows])
    if not e_new:
        return ErrorComparison(math.nan, math.inf, 0)
    ratio, se = _ratio_spread(np.concatenate(e_new), np.concatenate(e_run), chunk)
    return ErrorComparison(ratio, se, int(sum(e.size for e in e_new)))


def fold_correction(design: CompensatorDesign, correction: Correction) -> CompensatorDesign:
    """The compensator ``C K``: ``design``'s sections, its FIR refitted so that the whole
    matches ``C`` times ``K`` in the band and ``C`` outside it.

    The target runs it as any other compensator (same sections, preview and sizes).
    ``error`` of the result is against ``C K``. Preview mode only: ``K`` looks ``m``
    samples ahead, which the FIR's preview holds.

    Raises
    ------
    ParameterError
        A causal design (``K`` needs the reference ahead).
    """
    if design.mode != "preview" or design.preview < (correction.taps.size - 1) // 2:
        raise ParameterError("a correction looks ahead: it needs a compensator in "
                             "preview mode")
    return _realise(design.sos, design.inverse, design.band_hz, fs_hz=design.fs_hz,
                    mode=design.mode, preview=design.preview, n_taps=design.taps.size,
                    correction=(design, correction))
