"""Processing of one channel: the recursive estimator, the model's response, the
sliding H1 estimate and change detection.

The estimator is :class:`ehss.RelsEstimator` (RELS, eqs (19)–(22), or RML) with
forgetting λ, started from the baseline model's θ when one is given. The baseline's own
prediction errors, and the whitened output errors of its B/A refitted to the learning
time, run beside it; every evaluation period the median of each one's square over the
period feeds its sequential test, and the current model is compared with the reference
model for the figures (:mod:`ehss.live.detect`).
"""

from __future__ import annotations

import collections
import math
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import asdict, dataclass

import numpy as np
from scipy.signal import welch

import ehss
from ehss._checks import check_band, check_real
from ehss.errors import EhssError, ParameterError
from ehss.live.detect import (
    BaselineResidual,
    DetectionSettings,
    Detector,
    block_level,
    block_statistic,
    calibrate,
    check_baseline,
    dominant_pole,
    figures,
    level_of,
    output_error_predictor,
    rise_blocks,
)

__all__ = ["EstimatorSettings", "ChannelProcessor", "RefitTurns", "reference_band"]

#: points of the frequency grid of the analysis band
N_GRID = 64

#: The test's second predictor (the output errors of the baseline's B/A refitted to the
#: learning time) joins this long after the test starts, or after the turn of the
#: refit before it (:class:`RefitTurns`): its refit runs off the stream's thread
#: meanwhile (0.1–0.3 s of CPU a channel at 5 kHz, one channel after another; on the
#: stream's thread, 8 such channels held it for 1.4 s), and is waited for there only if
#: it is not in by then, so that a run is the same whatever the machine's speed.
SECOND_PREDICTOR_AFTER_S = 2.0

_REFITS: list[ThreadPoolExecutor] = []


def _refits() -> ThreadPoolExecutor:
    """The one thread the refits of every channel run on (started when first needed)."""
    if not _REFITS:
        _REFITS.append(ThreadPoolExecutor(max_workers=1, thread_name_prefix="ehss-refit"))
    return _REFITS[0]


class RefitTurns:
    """The turns of the refits that share the one refit thread (:func:`_refits`): each
    refit's predictor joins its test one turn (:data:`SECOND_PREDICTOR_AFTER_S`) after
    it was submitted or after the turn before it, whichever is later.

    The refits run one after another, so the k-th of N channels whose tests start
    together has its refit in after k refits' time: with one turn of
    :data:`SECOND_PREDICTOR_AFTER_S` each, the stream waits at a join only if one refit
    takes longer than that (10–20 times what it takes here at 5 kHz), not when N of
    them together do (8 channels at 5 kHz need 1.2 s here, more than 2 s on a machine
    twice as slow). The turns depend on the stream alone, so a run stays the same
    whatever the machine's speed. A session's channels share one.
    """

    def __init__(self) -> None:
        self._last = -math.inf

    def join_at(self, now: int, turn: int) -> int:
        """Book the turn of a refit submitted at block ``now`` (the count of the
        session's evaluations, which every channel shares), ``turn`` blocks long: the
        block its predictor joins at."""
        self._last = max(now, self._last) + turn
        return int(self._last)


@dataclass(frozen=True, kw_only=True)
class EstimatorSettings:
    """Settings of each channel's recursive estimator (see :func:`ehss.rels`).

    Attributes
    ----------
    na, nb, nc, delay : int
        Model structure.
    method : {"rels", "rml"}
        Default RML with nc = na: a rig's feedback carries mostly sensor noise (an
        output-error record), where RELS and least squares are biased and noisier.
    memory_s : float
        Memory of the forgetting factor: λ = 1 − 1 / (memory_s · fs), unless
        ``forgetting`` is given.
    forgetting : float or None
        λ itself.
    p0 : float
        α of P(0) = α I (on the scaled data). It also sets the bound of tr P (tr P(0)):
        a small α would hold P, and with it the tracking speed, below what the
        forgetting asks for.
    u_scale, y_scale : float or None
        Scales of u and y (see :class:`ehss.RelsEstimator`); None: the RMS of each
        channel's first ``scale_s`` of data (the estimator starts once it has them).
    scale_s : float
        Length of that first stretch, s.
    """

    na: int = 4
    nb: int = 3
    nc: int = 4
    delay: int = 1
    method: str = "rml"
    memory_s: float = 0.3
    forgetting: float | None = None
    p0: float = 1e6
    u_scale: float | None = None
    y_scale: float | None = None
    scale_s: float = 0.5

    def __post_init__(self) -> None:
        check_real(self.memory_s, "memory_s", lo=0.0, lo_open=True, unit="s")
        check_real(self.scale_s, "scale_s", lo=0.0, lo_open=True, unit="s")
        for name in ("u_scale", "y_scale"):  # None: from the data; 0 would divide by it
            if getattr(self, name) is not None:
                check_real(getattr(self, name), name, lo=0.0, lo_open=True)
        # the estimator checks the rest when it is built
        ehss.RelsEstimator(na=self.na, nb=self.nb, nc=self.nc, delay=self.delay,
                           method=self.method, p0=self.p0,
                           forgetting=1.0 if self.forgetting is None else self.forgetting,
                           u_scale=self.u_scale or 1.0, y_scale=self.y_scale or 1.0)

    def lam(self, fs: float) -> float:
        """λ at sample rate ``fs``."""
        if self.forgetting is not None:
            return float(self.forgetting)
        if self.memory_s * fs <= 1.0:
            raise ParameterError(f"memory_s={self.memory_s!r} s is not longer than one "
                                 f"sample at {fs:g} Hz ({1.0 / fs:g} s): the estimator "
                                 "would forget each sample as it comes")
        return 1.0 - 1.0 / (self.memory_s * fs)

    def memory(self, fs: float) -> float:
        """The memory 1/((1 − λ) fs) at sample rate ``fs``, s (``inf`` for λ = 1)."""
        lam = self.lam(fs)
        return math.inf if lam >= 1.0 else 1.0 / ((1.0 - lam) * fs)

    @property
    def n_params(self) -> int:
        return self.na + self.nb + 1 + self.nc

    def to_dict(self) -> dict:
        return asdict(self)


#: Fewest Welch segments (half overlapping) of a spectrum :func:`reference_band` reads a
#: band's lower edge from: the spectrum of each frequency then has about 2 × 8 degrees of
#: freedom (fewer for the overlap), within about −3 / +2 dB of the true level nine times
#: in ten.
BAND_SEGMENTS = 8


def _segments(n: int, nper: int) -> int:
    """Half-overlapping segments of ``nper`` samples in ``n``."""
    return 0 if nper > n else 1 + (n - nper) // (nper // 2)


def reference_band(u: np.ndarray, fs: float, *, resolution_hz: float = 0.5
                   ) -> tuple[float, float]:
    """Band where the spectrum of ``u`` is within 20 dB of its peak (Welch, Hann).

    Bins of about ``resolution_hz``. Each segment's mean is removed (a position
    reference has an offset), and what the 0-Hz bin then holds is that removal's and
    the window's leakage from the bins next to it (a reference flat from 1 Hz on gives
    18 dB below its peak there in 0.5-Hz bins, which would start its band at 0 Hz): a
    band that reaches the lowest two bins has its lower edge read again in bins four
    times finer, as long as the record holds :data:`BAND_SEGMENTS` segments of them, and
    starts at the first bin above 0 Hz at the lowest. The upper edge stays that of the
    coarser bins, whose leakage puts it up to a bin above the reference's last
    frequency: a compensator's fit is weighed by the band, and ends sharper at its edge
    than the target's FIR can follow (on the 4 kHz specimen loop of the tests, the band
    ended 0.04 Hz above a reference that stops at 40 Hz, not 0.53 Hz, left 6 % more
    tracking error).

    Raises
    ------
    ParameterError
        If ``u`` has no power.
    """
    # a power of two near fs / resolution
    nper = int(min(u.size, 2 ** max(4, round(math.log2(fs / resolution_hz)))))
    hi = None
    while True:
        f, p = welch(u, fs=fs, nperseg=nper)
        if not np.any(p > 0):
            raise ParameterError("the reference has no power: no band to analyse")
        keep = np.flatnonzero(p >= p.max() / 100.0)
        if hi is None:
            hi = float(f[keep[-1]])
        # Hann's main lobe spans two bins each side: an edge there is not resolved
        if keep[0] > 2 or _segments(u.size, 4 * nper) < BAND_SEGMENTS:
            break
        nper *= 4
    lo = float(f[max(keep[0], 1) if f.size > 1 else 0])
    if hi <= lo:
        hi = lo + fs / nper
    return lo, hi


class ChannelProcessor:
    """Estimation and detection for one channel.

    Parameters
    ----------
    name : str
    fs : float
        Sample rate, Hz.
    est : EstimatorSettings
    det : DetectionSettings
    baseline : ArmaxModel, optional
        Baseline model (refused when unstable or with absurd coefficients,
        :func:`~ehss.live.detect.check_baseline`): the estimator starts from its θ and
        detection tests against it. Without one, the baseline is the mean of the
        estimates over the second half of the first ``det.learn_s`` (the same estimator
        and memory as the comparisons: its figures then measure change, not the
        difference of two estimators).
    h1_window_s : float
        Length of the sliding window of the H1 estimate.
    refit_turns : RefitTurns, optional
        The turns of the second predictor's refit, shared by a session's channels
        (default: turns of this channel's own).
    """

    def __init__(self, name: str, fs: float, est: EstimatorSettings, det: DetectionSettings,
                 baseline: ehss.ArmaxModel | None = None, *, h1_window_s: float = 8.0,
                 refit_turns: RefitTurns | None = None) -> None:
        self.name = name
        self._turns = RefitTurns() if refit_turns is None else refit_turns
        self.fs = float(fs)
        self.est = est
        self.det = det
        if baseline is not None:
            check_baseline(baseline, f"channel {name}: the baseline model")
            if (baseline.na, baseline.nb, baseline.nc, baseline.delay) != (
                    est.na, est.nb, est.nc, est.delay):
                raise ParameterError(
                    f"channel {name}: the baseline model has structure (na, nb, nc, delay)="
                    f"{(baseline.na, baseline.nb, baseline.nc, baseline.delay)}, the "
                    f"estimator {(est.na, est.nb, est.nc, est.delay)}"
                )
            if not math.isclose(baseline.fs, self.fs, rel_tol=1e-9):
                raise ParameterError(f"channel {name}: the baseline model is at "
                                     f"{baseline.fs:g} Hz, the stream at {self.fs:g} Hz")
        self.baseline = baseline
        self.detector = Detector(det)
        self.estimator: ehss.RelsEstimator | None = None
        self._theta_sum: np.ndarray | None = None
        self._theta_count = 0
        self.just_set_up = False
        self._captured_learning = True
        self.n_samples = 0
        self.messages: list[str] = []
        if det.learn_s * self.fs > ehss.signals.MAX_SAMPLES:
            raise ParameterError(f"learn_s={det.learn_s!r} at {self.fs:g} Hz holds "
                                 f"{det.learn_s * self.fs:.3g} samples; at most "
                                 f"{ehss.signals.MAX_SAMPLES} are allowed")
        n_learn = max(1, int(round(det.learn_s * self.fs)))
        self._learn = (np.empty(n_learn), np.empty(n_learn))
        self._n_scale = max(1, int(round(est.scale_s * self.fs)))
        n_ring = max(16, int(round(h1_window_s * self.fs)))
        self._ring = np.zeros((2, n_ring))
        self._ring_fill = 0
        self._ring_pos = 0
        self.band_hz: tuple[float, float] | None = det.band_hz or (
            baseline.band_hz if baseline is not None else None)
        if det.band_hz is not None:
            check_band(det.band_hz, "band_hz", fs=self.fs)
        self.grid_hz: np.ndarray | None = None
        self._va: np.ndarray | None = None
        self._vb: np.ndarray | None = None
        self._h_ref: np.ndarray | None = None
        self._s_ref = complex("nan")
        self._recent: collections.deque = collections.deque()
        self.figures = np.full(4, np.nan)
        self.peak_figures = np.zeros(4)
        # the sequential test: its predictors' errors (the baseline's, and the whitened
        # output errors of its B/A refitted to the learning time), their values over
        # the current block, the block boundaries seen while learning, the samples
        # that came after the learning time before the test was set up
        self.residuals: list[BaselineResidual] = []
        self._res_block: list[list[np.ndarray]] = []
        # the second predictor while it is refitted: its future, the block it joins at,
        # the learning time's block spans it is calibrated on, and the samples since
        self._second: tuple[Future, int, list[tuple[int, int]]] | None = None
        #: whether the test has started at any time (with ``compare="recent"`` it stops
        #: while the loop is learnt anew)
        self.detection_began = False
        self._since: list[tuple[np.ndarray, np.ndarray] | None] = []   # None: a loss
        self._blocks = 0
        self._res_whole = False
        self.block_stat = np.full(0, math.nan)
        # the reference's sum of squares and samples in the current block (its level:
        # :func:`block_level`), and while the test is calibrated anew at a new test
        # level, the blocks' statistics and levels so far and how many it needs
        self._u_sq, self._u_n = 0.0, 0
        self.block_lvl = math.nan
        self._recal: tuple[list[np.ndarray], list[float], int] | None = None
        self._arl_blocks = math.inf
        self._marks: list[int] = []
        self._pending: list[tuple[np.ndarray, np.ndarray]] = []
        # the sample the learning time began at (later than 0 after a re-learning), and
        # the stream time of the last alarm
        self._learn_from = 0
        self._alarm_t = math.nan
        self.dominant = complex("nan")
        self.track_sq = 0.0
        self.pred_sq = 0.0
        self._acc_n = 0
        self.tracking_rms = math.nan
        self.prediction_rms = math.nan
        if est.u_scale is not None and est.y_scale is not None:
            self._start(est.u_scale, est.y_scale)

    # ------------------------------------------------------------------ feeding
    def _start(self, u_scale: float, y_scale: float) -> ehss.RelsEstimator:
        e = self.est
        theta0 = None if self.baseline is None else self.baseline.theta
        self.estimator = ehss.RelsEstimator(
            na=e.na, nb=e.nb, nc=e.nc, delay=e.delay, forgetting=e.lam(self.fs), p0=e.p0,
            theta0=theta0, dt=1.0 / self.fs, u_scale=u_scale, y_scale=y_scale,
            method=e.method,
        )
        return self.estimator

    def feed(self, u: np.ndarray, y: np.ndarray) -> None:
        """Process consecutive samples of the reference ``u`` and feedback ``y``."""
        k0 = self.n_samples
        n = u.size
        n_learn = self._learn[0].size
        r0 = k0 - self._learn_from            # place in the learning time
        if r0 < n_learn:
            m = min(n, n_learn - r0)
            self._learn[0][r0:r0 + m] = u[:m]
            self._learn[1][r0:r0 + m] = y[:m]
        if self.residuals:
            for k, residual in enumerate(self.residuals):
                self._res_block[k].append(residual(u, y))
            if self._second is not None:
                self._since.append((u.copy(), y.copy()))
            self._u_sq += float(np.dot(u, u))
            self._u_n += u.size
        elif self.grid_hz is None and r0 + n > n_learn:
            m = max(0, n_learn - r0)
            self._pending.append((u[m:].copy(), y[m:].copy()))
        self._push_ring(u, y)
        self.n_samples += n
        estimator = self.estimator
        if estimator is None:
            if self.n_samples < min(self._n_scale, n_learn):
                return
            estimator = self._start_on_learning(k0)
        err = estimator.update_many(u, y)
        self.pred_sq += float(np.dot(err, err))
        d = u - y
        self.track_sq += float(np.dot(d, d))
        self._acc_n += n

    def lost(self) -> None:
        """Samples were lost before the next ones fed: the test's predictors start their
        history afresh (:meth:`~ehss.live.detect.BaselineResidual.restart`)."""
        for residual in self.residuals:
            residual.restart()
        if self._second is not None:
            self._since.append(None)

    def _start_on_learning(self, k0: int) -> ehss.RelsEstimator:
        """Start the estimator with the scales of the learning buffer so far, and run it
        over the ``k0`` samples held before the current block (all in the buffer: the
        estimator starts no later than its end)."""
        have = min(self.n_samples, self._learn[0].size)
        uu, yy = self._learn[0][:have], self._learn[1][:have]
        su = float(np.sqrt(np.mean(uu**2))) or 1.0
        sy = float(np.sqrt(np.mean(yy**2))) or 1.0
        estimator = self._start(su, sy)
        if k0:
            estimator.update_many(uu[:k0], yy[:k0])
        return estimator

    def _push_ring(self, u: np.ndarray, y: np.ndarray) -> None:
        r = self._ring
        size = r.shape[1]
        if u.size >= size:
            r[0], r[1] = u[-size:], y[-size:]
            self._ring_pos, self._ring_fill = 0, size
            return
        a = self._ring_pos
        b = a + u.size
        if b <= size:
            r[0, a:b], r[1, a:b] = u, y
        else:
            k = size - a
            r[0, a:], r[1, a:] = u[:k], y[:k]
            r[0, :b - size], r[1, :b - size] = u[k:], y[k:]
        self._ring_pos = b % size
        self._ring_fill = min(size, self._ring_fill + u.size)

    def window(self) -> tuple[np.ndarray, np.ndarray]:
        """The latest samples (u, y) of the sliding window, oldest first."""
        r, n, p = self._ring, self._ring_fill, self._ring_pos
        if n < r.shape[1]:
            return r[0, :n].copy(), r[1, :n].copy()
        return np.roll(r[0], -p), np.roll(r[1], -p)

    # ------------------------------------------------------------------ evaluation
    @property
    def learning(self) -> bool:
        """True until the learning time is over and the baseline and band are set."""
        return self.grid_hz is None

    def _finish_learning(self) -> None:
        u = self._learn[0]
        if self.band_hz is None:
            # the last 4 s of the learning time, 0.5 Hz bins (coarser bins smear a band
            # that starts at 1 Hz down to 0 Hz): a few ms at most
            lo, hi = reference_band(u[-int(4 * self.fs):], self.fs)
            self.band_hz = (lo, hi)
        lo, hi = self.band_hz
        self.grid_hz = np.linspace(max(lo, 0.0), min(hi, 0.5 * self.fs), N_GRID)
        if self.baseline is None and self._theta_sum is not None and self._theta_count:
            # the mean of the estimates over the learning time's second half
            e = self.est
            th = self._theta_sum / self._theta_count
            try:
                self.baseline = ehss.ArmaxModel(
                    a=np.r_[1.0, th[:e.na]], b=th[e.na:e.na + e.nb + 1],
                    c=np.r_[1.0, th[e.na + e.nb + 1:]], delay=e.delay, dt=1.0 / self.fs,
                    meta={"baseline": "mean of the live estimates over "
                          f"{self._theta_count} evaluations"},
                )
            except EhssError as exc:
                self.messages.append(f"no baseline: {exc}")
        if self.baseline is not None:
            if not self.baseline.is_stable():
                self.messages.append("the baseline model is unstable: comparisons with it "
                                     "are not meaningful")
            self._h_ref = self.baseline.frequency_response(self.grid_hz)
            self._s_ref = dominant_pole(self.baseline.a, 1.0 / self.fs, self.band_hz)
            self._start_test(self.baseline)
        # z^-k on the grid, k = 0..na for A and d..d+nb for B: H = (V_b b) / (V_a a)
        e = self.est
        zi = np.exp(-2j * np.pi * self.grid_hz / self.fs)
        self._va = zi[:, None] ** np.arange(e.na + 1)
        self._vb = zi[:, None] ** (e.delay + np.arange(e.nb + 1))

    def _start_test(self, m: ehss.ArmaxModel) -> None:
        """Filter the learning time with the baseline, calibrate the test on its blocks'
        statistics (the last three quarters), catch up on the samples that came since,
        and start the refit of the second predictor on those three quarters, to join at
        its turn, :data:`SECOND_PREDICTOR_AFTER_S` later or more (:class:`RefitTurns`,
        :meth:`_join_second`; :mod:`ehss.live.detect`)."""
        u, y = self._learn
        n_learn = u.size
        marks = np.array([k for k in self._marks if n_learn // 4 <= k <= n_learn])
        if marks.size < 2:
            self.messages.append("detection off: the learning time holds too few "
                                 "evaluations to calibrate the test")
            return
        residual = BaselineResidual(m.a, m.b, m.c, m.delay)
        eps = residual(u, y)
        for uu, yy in self._pending:
            residual(uu, yy)
        self._pending = []
        spans = list(zip(marks[:-1].tolist(), marks[1:].tolist(), strict=True))
        x = np.array([block_statistic(eps[a:b]) for a, b in spans])
        levels = np.array([block_level(u[a:b]) for a, b in spans])
        block_s = float(np.median(np.diff(marks))) / self.fs
        # each of the two predictors' tests its half of the rate: the union's is the
        # one set
        arl_blocks = 2.0 * self.det.false_alarm_hours * 3600.0 / block_s
        self._arl_blocks = arl_blocks
        try:
            cal = calibrate(x, arl_blocks=arl_blocks, two_sided=self.det.compare == "recent")
        except EhssError as exc:
            self.messages.append(f"detection off: {exc}")
            return
        self.residuals, self._res_block = [residual], [[]]
        lag = int(round(self.det.recent_s / block_s)) if self.det.compare == "recent" else 0
        self.detector.start(cal, lag_blocks=max(lag, 1) if lag else 0, levels=levels)
        self.detection_began = True
        future = _refits().submit(output_error_predictor, m, u[marks[0]:].copy(),
                                  y[marks[0]:].copy())
        join = self._turns.join_at(
            self._blocks, max(1, int(round(SECOND_PREDICTOR_AFTER_S / block_s))))
        self._second, self._since = (future, join, spans), []
        self.messages.append(
            f"detection started: CUSUM threshold {cal.threshold:.2f} for one false alarm per "
            f"{self.det.false_alarm_hours:g} h, calibrated on {cal.n_blocks} blocks of learning "
            f"(worth {cal.n_effective:.0f} independent ones), each of its two predictors "
            f"set for half of that rate")

    def _join_second(self) -> None:
        """At its block, add the second predictor to the test (waiting for its refit if
        it is not in yet): calibrated on the learning time's blocks, brought up to the
        samples since, its CUSUM started."""
        assert self._second is not None
        future, _, spans = self._second
        self._second = None
        since, self._since = self._since, []
        try:
            residual = future.result()
        except (EhssError, np.linalg.LinAlgError, ValueError, FloatingPointError) as exc:
            # a record the fit cannot take (too short, singular, not finite)
            self.messages.append(f"the test watches the baseline's prediction errors "
                                 f"alone: the refit of its B/A failed ({exc})")
            return
        u, y = self._learn
        eps = residual(u, y)
        x = np.array([block_statistic(eps[a:b]) for a, b in spans])
        try:
            cal = calibrate(x, arl_blocks=self._arl_blocks,
                            two_sided=self.det.compare == "recent")
        except EhssError as exc:
            self.messages.append(f"the test watches the baseline's prediction errors "
                                 f"alone: {exc}")
            return
        for block in since:
            if block is None:
                residual.restart()
            else:
                residual(*block)
        self.residuals.append(residual)
        self._res_block.append([])
        self.detector.add(cal)
        self.messages.append("the test also watches the output errors of the baseline's "
                             "B/A refitted to the learning time, from here")

    def capture(self) -> np.ndarray | None:
        """θ̂ now (a copy; None before the estimator starts), and the tracking and
        prediction-error RMS over the samples since the last capture."""
        if self._acc_n:
            self.tracking_rms = math.sqrt(self.track_sq / self._acc_n)
            self.prediction_rms = math.sqrt(self.pred_sq / self._acc_n)
            self.track_sq = self.pred_sq = 0.0
            self._acc_n = 0
        self._captured_learning = self.n_samples - self._learn_from < self._learn[0].size
        if self.grid_hz is None:            # block boundaries until the set-up
            self._marks.append(self.n_samples - self._learn_from)
        # x = ln(median ε²) of the block since the last capture (a whole block only)
        self.block_stat = np.full(len(self.residuals), math.nan)
        self.block_lvl = math.nan
        if self._res_whole and self._res_block and self._res_block[0]:
            self.block_stat = np.array([block_statistic(np.concatenate(b))
                                        for b in self._res_block])
            self.block_lvl = level_of(self._u_sq, self._u_n)
        self._res_block = [[] for _ in self.residuals]
        self._u_sq, self._u_n = 0.0, 0
        self._res_whole = bool(self.residuals)
        self._blocks += 1
        if self._second is not None and self._blocks >= self._second[1] \
                and self.detector.started:
            self._join_second()       # at a block boundary: its first block is whole
        return None if self.estimator is None else self.estimator.theta

    def evaluate(self, t_s: float, theta: np.ndarray | None, *,
                 may_set_up: bool = True) -> str | None:
        """Compare the model θ̂ = ``theta`` (from :meth:`capture` at stream time
        ``t_s``) with the reference model; returns "alarm", "clear" or None.

        When the learning time is over, the first call with ``may_set_up`` sets the
        baseline, band and grid (:attr:`just_set_up` tells it did; a session lets one
        channel do so per evaluation, to spread the cost). Updates :attr:`figures` and
        :attr:`dominant`.
        """
        self.just_set_up = False
        if theta is None:
            return None
        if self._captured_learning:
            if self.baseline is None and \
                    self.n_samples - self._learn_from >= self._learn[0].size / 2:
                self._theta_sum = theta if self._theta_sum is None else self._theta_sum + theta
                self._theta_count += 1
            return None
        if self.grid_hz is None:
            if not may_set_up:
                return None
            self._finish_learning()
            self.just_set_up = True
        h, s = self._response(theta)
        self.dominant = s
        self._recalibrate()
        test = self.detector.statistic(self.block_stat, self.block_lvl)
        ref = self._reference(t_s, h, s)
        shown = np.full(3, np.nan) if ref is None else figures(h, *ref)
        self.figures = np.append(shown, test)
        finite = np.where(np.isfinite(self.figures), np.abs(self.figures), 0.0)
        if not self.detector.active:
            self.peak_figures = np.maximum(self.peak_figures, finite)
        change = self.detector.step(t_s, self.figures)
        if change == "level":
            cal = self.detector.calibration
            assert cal is not None
            self.messages.append(
                f"at {t_s:.2f} s the prediction errors rose with the reference's level (a "
                f"new test level, not a change of the loop): the test goes on at the new "
                f"level and is calibrated anew on the next {cal.n_blocks} blocks")
            self.detector.hold_at_new_level()
            self._recal = ([], [], cal.n_blocks)
            change = None
        if change == "alarm":
            self._alarm_t = t_s
        if self.det.compare == "recent" and self.detector.active and \
                t_s - self._alarm_t >= self.det.recent_s - 1e-9:
            self.messages.append(
                f"the loop has differed from its past for {self.det.recent_s:g} s: "
                f"learning it anew over {self.det.learn_s:g} s (the alarm clears when the "
                "test starts again)")
            self._relearn()
        return change

    def _recalibrate(self) -> None:
        """While the test is calibrated anew at a new test level (the baseline stays),
        take this block; start the test once it has as many as the first calibration
        had, and those of a rise's flagging after them (:func:`~ehss.live.detect.
        rise_blocks`: a change that comes at their end is tested, not learnt).
        Meanwhile the test goes on at the new level, from
        :data:`~ehss.live.detect.MIN_EFFECTIVE_BLOCKS` of its blocks on against their
        mean (:meth:`~ehss.live.detect.Detector.recentre`, those of the latest rise's
        flagging left out as well). An alarm meanwhile keeps that test: calibrated on
        blocks that hold the change, the new test would take it for the loop."""
        if self._recal is None:
            return
        if self.detector.active:
            self._recal = None
            return
        x, levels, need = self._recal
        if x and len(x[-1]) != self.block_stat.size:
            x.clear()                 # the second predictor joined: gather anew
            levels.clear()
        if self.block_stat.size and np.all(np.isfinite(self.block_stat)):
            x.append(self.block_stat)
            levels.append(self.block_lvl)
        cal = self.detector.calibration
        lag = rise_blocks(cal.threshold) if cal is not None else 0
        if len(x) < need + lag:
            if len(x) > lag:
                self.detector.recentre(np.array(x[:len(x) - lag]), levels[:len(x) - lag])
            return
        self._recal = None
        try:
            cals = [calibrate(xk, arl_blocks=self._arl_blocks)
                    for xk in np.array(x[:need]).T]
        except EhssError as exc:
            self.messages.append(f"detection off: {exc}")
            return
        self.detector.start(cals, levels=levels[:need])
        self.messages.append(f"detection started again at the new test level: CUSUM "
                             f"threshold {cals[0].threshold:.2f}")

    def _relearn(self) -> None:
        """Learn the baseline and calibrate the test anew, from the loop as it is now
        (``compare="recent"``, once a change has lasted ``recent_s``: the test's
        statistics of the learning time no longer describe the loop). The band stays."""
        self._learn_from = self.n_samples
        self._captured_learning = True
        self.baseline, self._theta_sum, self._theta_count = None, None, 0
        self.grid_hz, self._h_ref, self._s_ref = None, None, complex("nan")
        self.residuals, self._res_block, self._res_whole = [], [], False
        self._second, self._since = None, []
        self._u_sq, self._u_n, self._recal = 0.0, 0, None
        self._marks, self._pending = [], []
        self._alarm_t = math.nan
        self.detector.restart()

    def _reference(self, t_s: float, h: np.ndarray, s: complex
                   ) -> tuple[np.ndarray, complex, complex] | None:
        """``(h_ref, s, s_ref)`` to compare ``h`` with (the baseline's, or the model's of
        ``recent_s`` ago); None while there is none."""
        if self.det.compare == "recent":
            self._recent.append((t_s, h, s))
            while self._recent and self._recent[0][0] < t_s - self.det.recent_s - 1e-9:
                self._recent.popleft()
            if self._recent[0][0] > t_s - self.det.recent_s + 1e-9:
                return None                      # not enough history yet
            _, h_ref, s_ref = self._recent[0]
            return h_ref, s, s_ref
        if self._h_ref is None:
            return None
        return self._h_ref, s, self._s_ref

    def _response(self, theta: np.ndarray) -> tuple[np.ndarray, complex]:
        """The response of the model θ̂ on the grid and its dominant pole.

        The same G(e^{jωdt}) = e^{−jωdt·d} B/A as :meth:`ArmaxModel.frequency_response`,
        from θ̂ through precomputed powers of z⁻¹ (no model object per evaluation).
        """
        e = self.est
        a = np.concatenate(([1.0], theta[:e.na]))
        b = theta[e.na:e.na + e.nb + 1]
        return (self._vb @ b) / (self._va @ a), dominant_pole(a, 1.0 / self.fs, self.band_hz)

    def model_response(self) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
        """``(grid_hz, current model's H, reference H)`` on the band grid."""
        if self.grid_hz is None or self.estimator is None or self._va is None:
            return np.empty(0), None, None
        return self.grid_hz, self._response(self.estimator.theta)[0], self._h_ref

    def h1(self) -> ehss.FrequencyResponse | None:
        """H1 estimate over the sliding window, or None while it is too short."""
        u, y = self.window()
        if u.size < 256:
            return None
        try:
            return ehss.h1_estimate(u, y, fs=self.fs)
        except EhssError:
            return None
