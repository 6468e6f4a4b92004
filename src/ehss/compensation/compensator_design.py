"""The compensator a real-time target runs, designed from a model of its closed loop.

A rig identified online (:class:`ehss.RelsEstimator`) has, at any time, a model
``G = q^-d B/A`` of its closed loop. :func:`design_compensator` turns it into the
compensator a real-time target runs (:mod:`ehss.target.filter`): second-order sections,
an FIR part and an integer preview ``P``,

.. math:: C(q) = q^{P}\\, S(q^{-1})\\, H(q^{-1}),

with ``S = A / (k B_i)`` the exact inverse of the model's minimum-phase part (the
sections of :func:`ehss.compensation.design_inverse`'s causal filter) and ``H`` an FIR
of ``n_taps`` taps fitted by weighted least squares so that ``C`` matches, over the
whole frequency axis, the compensator that ``ehss compensate`` applies to a drive file:

.. math:: T(\\omega) = W(\\omega)\\, F(\\omega) + (1 - W(\\omega)),

the exact stable inverse ``F`` inside the band limit ``W`` (the band the model is
validated over), the reference itself outside it. The FIR carries everything that is
not causal and minimum phase: the delay's advance ``q^d``, the anti-causal inverse of
the non-minimum-phase zeros, the zeros near the unit circle and the band limit.
:func:`run_compensator` computes the drive it gives for a reference over a record.

Two reference modes:

* **preview** (the reference is known ahead, a drive file streamed): ``P`` samples of
  it are known, and the FIR spans ``P`` samples of the future. The fit is then exact
  up to what the anti-causal part leaves beyond ``P`` samples (its error is reported).
* **causal** (the reference is made online, ``P = 0``): the same fit with a causal FIR,
  i.e. the least-squares causal predictor of the exact inverse over the band. It leaves
  amplitude and phase errors, reported per design (:attr:`CompensatorDesign.errors`).

References: eqs (16)–(22) of the paper (the model and its recursive estimate).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
import scipy.linalg
import scipy.signal

from ehss._checks import check_int, check_real
from ehss._settle import settle_samples
from ehss.compensation.inverse import InverseModel, design_inverse
from ehss.errors import ParameterError
from ehss.identification.model import ArmaxModel

if TYPE_CHECKING:
    # only _realise's annotation: the correction module imports this one
    from ehss.compensation.correction import Correction

__all__ = [
    "FEWEST_TAPS",
    "FIR_SPAN_S",
    "MODES",
    "CompensatorDesign",
    "design_compensator",
    "fir_modes_hz",
    "fir_taps",
    "pass_through",
    "run_compensator",
]

#: Reference modes: known ahead (a drive file streamed) or made online.
MODES = ("preview", "causal")

#: Time the FIR part spans by default, s (:func:`fir_taps`). What it must realise is
#: set in hertz (the band limit's transition above the band, 10 Hz wide for a band to
#: 20 Hz; the inverse near the band's edges), so its length in samples follows the rate.
#: Over 0.5-20 Hz the simulated rig's inverse (model (6, 5, 6) identified on 30 s)
#: is realised to 0.22-0.24 % RMS with 0.256 s at 1, 2 and 5 kHz (256, 512 and 1280
#: taps), against 1.4 % and 5.9 % with 256 taps at 2 and 5 kHz.
FIR_SPAN_S = 0.256

#: Fewest taps :class:`~ehss.compensation.adaptive.AdaptiveCompensator` tries before
#: longer FIRs (``fewest_taps`` of :func:`design_compensator`): the 256 that span
#: :data:`FIR_SPAN_S` at 1 kHz, so that a design at 1 kHz or below has one length.
FEWEST_TAPS = 256


def fir_taps(fs_hz: float, preview: int = 0, most: int | None = None) -> int:
    """FIR length of a compensator at ``fs_hz`` by default: :data:`FIR_SPAN_S` of
    samples (rounded up), at least ``2 * preview`` (the preview is half of it), at
    most ``most`` (a target's capacity, :data:`ehss.target.MAX_TAPS` for ehss's own).

    >>> fir_taps(1000.0), fir_taps(5000.0), fir_taps(500.0, preview=128)
    (256, 1280, 256)
    >>> fir_taps(2e4), fir_taps(2e4, most=2048)
    (5120, 2048)
    """
    fs_hz = check_real(fs_hz, "fs_hz", lo=0.0, lo_open=True, unit="Hz")
    want = max(int(math.ceil(FIR_SPAN_S * fs_hz - 1e-9)), 2 * int(preview), 1)
    return want if most is None else min(want, int(most))


#: Weights of the fit (inside the band, in the band limit's transitions, outside its
#: support), per mode: the squared error at each frequency counts by the reference's
#: power there. Preview: the exact inverse in the band, and 1 % (20 dB down, the edge of
#: the reference's band, :func:`ehss.live.reference_band`) in the transitions and
#: outside. A transition narrower than the FIR's resolution (fs / n_taps: 0.25 Hz wide
#: at a 0.5 Hz edge, against 4 Hz for 256 taps at 1 kHz) cannot be realised; weighed
#: like the band it took taps from the band's fit (0.09–0.19 dB / 0.4–1.1° there on the
#: simulated rig, 0.10–0.21 dB / 0.3–0.5° weighed at 1 %). Causal:
#: the fit is the least-squares causal *prediction* of the exact inverse for a reference
#: that has its power in the band: 30 dB down in the transitions, 60 dB outside (a
#: band-limited reference); it buys its accuracy in the band with gain outside it
#: (:attr:`CompensatorDesign.peak_gain`), which the drive checks bound.
_WEIGHTS = {"preview": (1.0, 1e-2, 1e-2), "causal": (1.0, 1e-3, 1e-6)}


@dataclass(frozen=True, kw_only=True)
class CompensatorDesign:
    """A compensator as a target runs it, and what it costs against the exact inverse.

    Attributes
    ----------
    sos : ndarray, shape (n_sections, 6)
        Second-order sections (scipy's layout), ``S = A/(k B_i)`` (the zeros of ``B_i``
        whose modes outlast an eighth of the FIR are left to the FIR, unless the band
        reaches down to them: :func:`design_compensator`).
    taps : ndarray, shape (n_taps,)
        FIR part after the sections.
    preview : int
        Samples of reference the filter's input runs ahead of the drive.
    fs_hz : float
    mode : {"preview", "causal"}
    band_hz : (float, float)
        Band the model is trusted over (the inverse's band limit).
    inverse : InverseModel
        The exact stable inverse it realises (:func:`design_inverse`).
    freq_hz : ndarray
        Grid over the band where the errors were computed.
    error : ndarray, complex
        ``C / T - 1`` on that grid: the relative error against the exact inverse (what
        the loop's response differs from 1 by, if the model is right).
    peak_gain : float
        Largest ``|C|`` from 0 to fs/2 (what the compensator can amplify).
    settle_samples : int
        Samples the filter needs to forget its start (sections' slowest mode, FIR span:
        :func:`ehss._settle.settle_samples`, the rule the target's filter applies too).
    """

    sos: np.ndarray = field(repr=False)
    taps: np.ndarray = field(repr=False)
    preview: int
    fs_hz: float
    mode: str
    band_hz: tuple[float, float]
    inverse: InverseModel = field(repr=False)
    freq_hz: np.ndarray = field(repr=False)
    error: np.ndarray = field(repr=False)
    peak_gain: float
    settle_samples: int

    @property
    def max_amplitude_error_db(self) -> float:
        """Largest ``|20 log10 |C/T||`` over the band, dB."""
        return float(np.max(np.abs(20.0 * np.log10(np.abs(1.0 + self.error)))))

    @property
    def max_phase_error_deg(self) -> float:
        """Largest ``|arg(C/T)|`` over the band, degrees."""
        return float(np.max(np.abs(np.degrees(np.angle(1.0 + self.error)))))

    def frequency_response(self, freq_hz: Any) -> np.ndarray:
        """Complex response ``C(e^{jω})`` of the compensator at ``freq_hz``."""
        return _realised(self.sos, self.taps, self.preview,
                         np.asarray(freq_hz, dtype=float) / self.fs_hz)

    def errors(self) -> dict[str, float]:
        """JSON-ready figures: max amplitude (dB) and phase (degrees) error over the band,
        the filter's largest gain at any frequency (``filter_peak_gain``: not the drive's
        peak against the reference's, ``peak_gain`` of the drive checks, which a load's
        figures carry beside it), and the RMS relative error."""
        return {"max_amplitude_error_db": self.max_amplitude_error_db,
                "max_phase_error_deg": self.max_phase_error_deg,
                "filter_peak_gain": self.peak_gain,
                "rms_relative_error": float(np.sqrt(np.mean(np.abs(self.error) ** 2)))}


def _sections(num: np.ndarray, den: np.ndarray) -> np.ndarray:
    """``num/den`` (ascending powers of q^-1) as second-order sections."""
    n = max(num.size, den.size)
    b = np.zeros(n)
    a = np.zeros(n)
    b[:num.size] = num
    a[:den.size] = den
    if n == 1:
        return np.array([[b[0] / a[0], 0.0, 0.0, 1.0, 0.0, 0.0]])
    return np.ascontiguousarray(scipy.signal.tf2sos(b, a))


def _fir_limit(n_taps: int) -> float:
    """Radius of the slowest mode a section takes by default: one that dies out (by
    e^-8) within the FIR's span; slower ones are left to the FIR."""
    return math.exp(-8.0 / n_taps)


def _fast_part(den: np.ndarray, n_taps: int, slowest: float = 0.0) -> np.ndarray:
    """The factor of ``den`` (monic, roots inside the unit circle) whose modes die out
    within an eighth of the FIR's span, or whose radius is at most ``slowest``; the
    slower ones are left to the FIR's fit.

    A zero of the model close to ``z = 1`` gives the inverse a mode of seconds; run as a
    section it would need seconds in shadow before each update could be faded in. Where
    its effect lies below the band, the target there is the reference itself and the FIR
    fits it; where it reaches into the band, only a section realises it
    (:func:`design_compensator`).
    """
    roots = np.roots(den) if den.size > 1 else np.zeros(0, complex)
    fast = roots[np.abs(roots) <= max(_fir_limit(n_taps), slowest)]
    return np.real_if_close(np.poly(fast), tol=1e6).real if fast.size else np.ones(1)


def fir_modes_hz(design: CompensatorDesign) -> np.ndarray:
    """Frequencies (Hz, from 0 to fs/2) of the inverse's modes that ``design`` leaves to
    its FIR: those that outlast an eighth of its span (:func:`design_compensator`).

    Near 0 Hz such a mode is a model's zero close to ``z = 1``, whose effect lies below
    the band; at the band's frequencies it is a lightly damped resonance of the inverse
    (a model's zero pair beside a mode of the loop), which the FIR cannot realise."""
    if design.inverse.den.size < 2:
        return np.zeros(0)
    roots = np.roots(design.inverse.den)
    run = np.concatenate([np.roots(sec[3:]) for sec in design.sos])  # the sections' poles
    left = [r for r in roots
            if abs(r) > _fir_limit(design.taps.size)
            and (run.size == 0 or np.min(np.abs(run - r)) > 1e-6)]
    return np.abs(np.angle(np.asarray(left, complex))) * design.fs_hz / (2.0 * math.pi)


def _slowest_section(fs: float, lo: float) -> float:
    """Radius of the slowest mode a section may take when the FIR cannot realise it:
    one whose corner is a quarter of the band's lower edge (its settling, seven time
    constants, is then ``4.46 / lo`` s: 4.5 s for a band from 1 Hz). A slower mode acts
    in the band as an integrator whatever its radius, and would hold every update in
    shadow longer than a loop's change takes to follow. 0 (none) for a band from DC."""
    return math.exp(-2.0 * math.pi * (lo / 4.0) / fs) if lo > 0 else 0.0


def _rms_error(design: CompensatorDesign) -> float:
    return float(np.sqrt(np.mean(np.abs(design.error) ** 2)))


def _sos_response(sos: np.ndarray, w: np.ndarray) -> np.ndarray:
    h = np.ones(w.shape, complex)
    x = np.exp(-1j * w)
    for b0, b1, b2, a0, a1, a2 in sos:
        h *= (b0 + b1 * x + b2 * x * x) / (a0 + a1 * x + a2 * x * x)
    return h


def _realised(sos: np.ndarray, taps: np.ndarray, preview: int, f_norm: np.ndarray
              ) -> np.ndarray:
    """``e^{jωP} S(ω) H(ω)`` at normalised frequencies ``f/fs``."""
    w = 2.0 * np.pi * f_norm
    fir = np.exp(-1j * np.outer(w, np.arange(taps.size))) @ taps
    return np.exp(1j * w * preview) * _sos_response(sos, w) * fir


def _fit_taps(s_resp: np.ndarray, target: np.ndarray, weight: np.ndarray, preview: int,
              n_taps: int) -> np.ndarray:
    """Weighted least squares: ``min sum weight |e^{jωP} S H - T|^2`` over real taps.

    On the uniform grid ``ω_k = π k / K`` (k = 0..K) with the FIR's columns
    ``e^{jω(P-j)} S(ω)``, the normal equations' matrix is Toeplitz,
    ``R[i, j] = sum weight |S|^2 cos(ω (i - j))``, and the right-hand side
    ``b[j] = sum weight Re(conj(S) T e^{jω(j-P)})``: both are inverse FFTs of length 2K,
    and Levinson's recursion solves the equations in O(n_taps^2).
    """
    k = s_resp.size - 1
    c = weight * np.abs(s_resp) ** 2
    r = np.fft.ifft(np.concatenate([c, np.zeros(k - 1)])).real[:n_taps]
    g = weight * np.conj(s_resp) * target
    lag = (np.arange(n_taps) - preview) % (2 * k)
    b = np.fft.ifft(np.concatenate([g, np.zeros(k - 1)]))[lag].real
    # a relative 1e-10 on the diagonal: the taps stay bounded where the weight is small
    r[0] *= 1.0 + 1e-10
    return scipy.linalg.solve_toeplitz(r, b)


def _grid_size(fs: float, band: tuple[float, float], n_taps: int) -> int:
    """K of the grid ``f_k = k fs / (2K)``: 8 points per tap, and 8 across the band
    limit's lower transition (``lo/2`` wide) up to 2**14 points.

    The FIR part resolves no detail finer than ``fs / n_taps``; 8 grid points per tap
    sample the weighted error it is fitted to below that. A finer grid changes the fit
    by nothing the filter can realise and costs its size in every FFT: at 5 kHz over
    0.5-20 Hz, 1280 taps realise the simulated rig's inverse to 0.23 % RMS / 0.3° on
    2**14 points (11 ms a design), 2**15 (15 ms) and the 2**17 that 8 points across the
    0.25 Hz transition would ask (96 ms) alike, checked on 4000 points in the band.
    """
    lo = band[0] if band[0] > 0 else band[1]
    want = max(8 * n_taps, min(8.0 * fs / lo, 2.0**14))
    return int(2 ** math.ceil(math.log2(want)))


def design_compensator(model: ArmaxModel, *, band_hz: tuple[float, float] | None = None,
                       mode: str = "preview", preview: int | None = None,
                       n_taps: int | None = None, max_sections: int = 16,
                       within: tuple[float, float] = (1.0, 5.0),
                       fewest_taps: int | None = None) -> CompensatorDesign:
    """The compensator of ``model`` as sections, an FIR part and a preview.

    Parameters
    ----------
    model : ArmaxModel
        Closed-loop model (reference → feedback), e.g. ``RelsEstimator.model``.
    band_hz : (lo, hi), optional
        Band the model is trusted over (default ``model.band_hz``; one is needed).
    mode : {"preview", "causal"}
    preview : int, optional
        Samples known ahead in preview mode (default ``n_taps // 2``); must be 0 or
        absent in causal mode.
    n_taps : int, optional
        FIR length, at most the target's (default :func:`fir_taps` of the model's rate
        and ``preview``: :data:`FIR_SPAN_S` of samples).
    max_sections : int
        Most second-order sections the target runs.
    within : (dB, degrees)
        How closely the filter must realise the inverse over the band before its slow
        modes are tried as sections (default the bounds a model must meet against the
        H1 estimate, :class:`ehss.workflow.Acceptance`). The inverse's modes that
        outlast an eighth of the FIR are left to the FIR, which fits them below the
        band; where the band reaches down to them (a loop with a high-pass near its
        lower edge: an AC-coupled sensor, a shaking table's acceleration generator)
        the FIR cannot, and the modes no slower than a quarter of the band's lower
        edge are run as sections instead, if that realises the inverse better: each
        update then settles longer in shadow (:attr:`CompensatorDesign.settle_samples`,
        up to ``4.46 / lo`` s).
    fewest_taps : int, optional
        Try FIRs from this many taps up, doubling to ``n_taps``, and keep the longest
        that halved the realisation's RMS error against the one half its length: a
        longer FIR settles longer in shadow before each update, and pays only where
        the span was what limited it (the simulated rig's inverse at 5 kHz: 6 %, 2 %,
        0.4 % with 256, 512 and 1024 taps; a 4 kHz specimen loop whose preview of 128
        samples limits it: 0.59 % and 0.53 % with 256 and 512). Default: ``n_taps``
        only.

    Returns
    -------
    CompensatorDesign

    Raises
    ------
    ParameterError
        No band, a bad mode, preview or size, or a model that cannot be inverted
        (:func:`ehss.compensation.design_inverse`: unstable, zero on the unit circle in
        the band).

    Examples
    --------
    >>> from ehss.identification.model import ArmaxModel
    >>> m = ArmaxModel(a=[1.0, -0.9], b=[0.1], delay=1, dt=1e-3)
    >>> d = design_compensator(m, band_hz=(1.0, 50.0), n_taps=256)
    >>> d.preview, bool(d.max_amplitude_error_db < 0.05), bool(d.max_phase_error_deg < 0.1)
    (128, True, True)

    The FIR must resolve the band limit's lowest edge: 64 taps (64 ms at 1 kHz) leave
    about 0.3 dB / 0.4° near 1 Hz.
    """
    if not isinstance(model, ArmaxModel):
        raise TypeError(f"model must be an ArmaxModel, not {type(model).__name__}")
    if mode not in MODES:
        raise ParameterError(f"mode={mode!r} must be one of {MODES}")
    n_taps = fir_taps(model.fs, preview or 0) if n_taps is None \
        else check_int(n_taps, "n_taps", lo=1)
    preview = _check_preview(mode, preview, n_taps)
    within = _check_within(within)
    band = band_hz if band_hz is not None else model.band_hz
    if band is None:
        raise ParameterError("the compensator needs the band the model is trusted over: "
                             "give band_hz (or a model with one)")
    inv = design_inverse(model, band_hz=band)
    # the band the inverse was limited to (it was given one)
    inv_band = inv.band_hz if inv.band_hz is not None else (float(band[0]), float(band[1]))
    lengths = [n_taps]
    if fewest_taps is not None:
        fewest = check_int(fewest_taps, "fewest_taps", lo=max(1, preview + 1))
        while lengths[0] // 2 >= fewest:
            lengths.insert(0, lengths[0] // 2)
    best = None
    for n in lengths:
        design = _design_at(inv, inv_band, model.fs, mode, preview, n, max_sections, within)
        if best is not None and _rms_error(design) > 0.5 * _rms_error(best):
            break                        # twice the taps did not halve the error
        best = design
    assert best is not None
    return best


def _design_at(inv: InverseModel, inv_band: tuple[float, float], fs: float, mode: str,
               preview: int, n_taps: int, max_sections: int,
               within: tuple[float, float]) -> CompensatorDesign:
    """The design of ``n_taps``: the modes the FIR takes first; if it then misses
    ``within``, those of them that reach into the band go to the sections as well, if
    that realises the inverse better."""
    fast = _fast_part(inv.den, n_taps)
    more = _fast_part(inv.den, n_taps, _slowest_section(fs, inv_band[0]))
    design = None
    for den in (fast, more) if more.size > fast.size else (fast,):
        sos = _sections(inv.num, den)
        if sos.shape[0] > max_sections:
            raise ParameterError(f"the inverse needs {sos.shape[0]} second-order sections, "
                                 f"the target runs {max_sections}; identify a lower order")
        got = _realise(sos, inv, inv_band, fs_hz=fs, mode=mode, preview=preview,
                       n_taps=n_taps)
        if design is None or _rms_error(got) < _rms_error(design):
            design = got
        if design.max_amplitude_error_db <= within[0] \
                and design.max_phase_error_deg <= within[1]:
            break
    assert design is not None
    return design


def _realise(sos: np.ndarray, inv: InverseModel, band: tuple[float, float], *,
             fs_hz: float, mode: str, preview: int, n_taps: int,
             correction: tuple[CompensatorDesign, Correction] | None = None
             ) -> CompensatorDesign:
    """The FIR after ``sos`` fitted to ``T = W F + (1 - W)``; with ``correction``
    (the running design, of the same sections, and a correction ``K``) to the running
    design's own response times ``W K + (1 - W)``
    (:func:`~ehss.compensation.correction.fold_correction`)."""
    lo, hi = band
    k = _grid_size(fs_hz, band, n_taps)
    f = np.arange(k + 1) * (0.5 * fs_hz / k)
    w = np.pi * np.arange(k + 1) / k
    band_w = inv.band_response(f)
    s_resp = _sos_response(sos, w)
    if correction is None:
        # T = W F + (1 - W): the exact inverse in the band, the reference outside it
        target = inv.frequency_response(f, band=True) + (1.0 - band_w)
    else:
        running, kappa = correction
        # T = C_run (W K + (1 - W)): the correction in the band, nothing outside it
        c_run = np.exp(1j * w * preview) * s_resp * np.fft.rfft(running.taps, 2 * k)
        target = c_run * (band_w * kappa.frequency_response(f) + (1.0 - band_w))
    w_in, w_edge, w_out = _WEIGHTS[mode]
    weight = np.where(band_w >= 1.0, w_in, np.where(band_w > 0.0, w_edge, w_out))
    taps = _fit_taps(s_resp, target, weight, preview, n_taps)
    # C = e^{jωP} S H on the grid
    got = np.exp(1j * w * preview) * s_resp * np.fft.rfft(taps, 2 * k)
    inside = (f >= lo) & (f <= hi)
    return CompensatorDesign(
        sos=sos, taps=np.ascontiguousarray(taps), preview=int(preview), fs_hz=float(fs_hz),
        mode=mode, band_hz=(float(lo), float(hi)), inverse=inv, freq_hz=f[inside],
        error=got[inside] / target[inside] - 1.0, peak_gain=float(np.max(np.abs(got))),
        settle_samples=settle_samples(sos, taps.size),
    )


def _check_within(within: Any) -> tuple[float, float]:
    """``within`` as (dB, degrees), each positive (inf: no bound)."""
    try:
        db, deg = within
    except (TypeError, ValueError):
        raise ParameterError(f"within={within!r} must be a pair (dB, degrees)") from None
    return (db if db == math.inf else check_real(db, "within dB", lo=0.0, lo_open=True),
            deg if deg == math.inf else check_real(deg, "within degrees", lo=0.0,
                                                   lo_open=True))


def _check_preview(mode: str, preview: Any, n_taps: int) -> int:
    if mode == "causal":
        if preview not in (None, 0):
            raise ParameterError(f"preview={preview!r}: the causal mode has none (0)")
        return 0
    if preview is None:
        return n_taps // 2
    return check_int(preview, "preview", lo=0, hi=n_taps - 1)


def pass_through(fs_hz: float, band_hz: tuple[float, float], *, mode: str = "preview",
                 preview: int | None = None, n_taps: int | None = None
                 ) -> CompensatorDesign:
    """The compensator that passes the reference as it is (drive = reference), in the
    form :func:`design_compensator` gives for ``mode``, ``preview`` and ``n_taps``
    (default :func:`fir_taps`):
    what a target runs with compensation off. Its FIR ends at the one tap it needs
    (``preview + 1`` taps), so that a target takes it up after that many samples, the
    fewest its filter's rule allows (:func:`ehss._settle.settle_samples`).

    >>> d = pass_through(1000.0, (0.5, 20.0), preview=128)
    >>> d.preview, d.taps.size, float(d.taps[128]), d.peak_gain, d.settle_samples
    (128, 129, 1.0, 1.0, 129)
    """
    identity = ArmaxModel(a=np.ones(1), b=np.ones(1), delay=0, dt=1.0 / fs_hz)
    design = design_compensator(identity, band_hz=band_hz, mode=mode, preview=preview,
                                n_taps=n_taps)
    taps = np.zeros(design.preview + 1)
    taps[-1] = 1.0
    return dataclasses.replace(design, taps=taps, error=np.zeros_like(design.error),
                               peak_gain=1.0,
                               settle_samples=settle_samples(design.sos, taps.size))


def run_compensator(design: CompensatorDesign, reference: Any) -> np.ndarray:
    """The drive ``design`` gives for ``reference`` over a record, started at rest.

    ``u[k] = (h * S r)[k + P]``: the same sections and FIR the target runs, with the
    reference known to the record's end (held at its last value beyond it).

    Parameters
    ----------
    design : CompensatorDesign
    reference : array_like, shape (n,)

    Returns
    -------
    ndarray, shape (n,)
    """
    r = np.asarray(reference, dtype=float)
    p = design.preview
    x = np.concatenate([r[p:], np.full(min(p, r.size), r[-1] if r.size else 0.0)])
    v = scipy.signal.sosfilt(design.sos, x)
    return scipy.signal.lfilter(design.taps, [1.0], v)
