"""Change detection calibrated to the loop it watches: a sequential test (CUSUM) on the
baseline model's prediction errors, with a false-alarm rate the user sets, and the
figures engineers read.

The test
--------
The baseline model (given, or learned) predicts each feedback sample from the past:
ε(t) = [A(q) y(t) − q^{-d} B(q) u(t)] / C(q) (the ARMAX prediction error, eq (19) of
the paper written as a filter; C with any root outside the unit circle reflected
inside, the same spectrum and a stable filter). While the loop is the one the baseline
describes, the size of ε over each evaluation block (``update_s``, 0.1 s) has a
stationary distribution, whatever the loop; a change of the loop adds the difference of
the two responses, driven by the reference, and raises it.

A second predictor runs beside it (:func:`output_error_predictor`): the output errors
of the baseline's B/A refitted to the learning time, whitened by their
autoregression, ε₂ = D(q) [y − q^-d (B/F) u]. The first leans on the past feedback as
much as C lets it, and a baseline averaged from the live estimates can have a C that
predicts a changed loop nearly as well as the one it learnt (a 15 Hz loop with a
lightly damped 40 Hz oil-column mode: +40 % mass raised its statistic by 1–2 σ, and was
flagged 0.6–5.4 s after it came); the second leans on the reference (15–23 σ there),
but sees less of a slow loop's change once whitened (a 4 Hz loop at 500 Hz: 2.4–4 σ
against 6–8 σ). Each has its own test below, calibrated on its own blocks for half the
false-alarm rate; an alarm comes from either. The statistic of block k is, for each,

    x_k = ln( median of ε² over block k ),

close to Gaussian. The median, not the mean: a few samples of a block that a linear
model misses by far (a valve's flow nonlinearity at the reference's peaks) give the mean
square a heavy upper tail (skewness 1.8, kurtosis 7 on the simulated rig's position
loop), which a test calibrated on a Gaussian would take for a change; the median of the
same blocks has none (skewness 0.0, kurtosis 0.2), and a change of the loop raises every
sample's error, so the median too.

Its mean μ and spread are measured over the learning time (the last three quarters of
``learn_s``; the first quarter is left to the start of the run), with the blocks'
autocorrelation: the long-run variance σ² = s² (1 + ρ)/(1 − ρ) (ρ the lag-1
autocorrelation, counted when positive: the AR(1) form) is the variance a sum of
correlated blocks grows with, and n_eff = n s²/σ² the number of independent blocks the
learning time held. The prediction errors of a fixed model are correlated over the
loop's and the reference's memory (tens of ms), so blocks of 0.1 s are nearly
independent (|ρ| ≤ 0.11 on the loops of the tests), unlike the recursive estimates,
correlated over the estimator's memory. The second predictor's are too, but on the loop
behind a 0.5 Hz high-pass (ρ 0.67–0.76): its refit misses the slow mode, and the miss,
driven by the reference's low end, outlasts a block; there the learning time counts
for fewer independent blocks, and the test is set wider. Both are taken at their one-sided 97.5 %
confidence bounds over that many blocks (μ + t·σ/√n_eff; σ·√((n_eff − 1)/χ²_0.025)), so
that the stated rate is not broken by what a short learning time cannot know.

The standardised z_k = (x_k − μ)/σ drive, for each predictor, a one-sided CUSUM
(Page's test; Basseville & Nikiforov 1993; Gustafsson 2000):

    S_k = max(0, S_{k−1} + z_k − κ),   alarm when S_k ≥ h,

with the drift κ = 1/2 (the test is quickest for a rise of one σ; a change of a loop's
dynamics raises x by many σ and is flagged within a block or two). The threshold h sets
the average run length between false alarms, ARL₀ = T / update_s for a mean time T
between false alarms (``false_alarm_hours``); Siegmund's approximation for Gaussian
increments (Siegmund 1985; Basseville & Nikiforov 1993):

    ARL₀(h) ≈ (e^{2κb} − 1 − 2κb) / (2κ²),   b = h + 1.166,

solved for h, each predictor's for twice the run length (its half of the rate: the
union of the two tests raises false alarms at most at the rate set). After samples are
lost the predictors start their history afresh and give no block until that start has
died out (:meth:`BaselineResidual.restart`). With ``compare="recent"`` the test is
two-sided on x_k − x_{k−R}, the statistic now against its value ``recent_s`` ago
(standard deviation √2 σ, mean 0): a change is flagged when it comes, a slow drift is
not. A change that lasts ``recent_s`` leaves the learning time's statistics behind (a
changed loop's errors spread differently), so the channel then learns the loop anew
and the alarm clears when the new test starts
(:class:`~ehss.live.channel.ChannelProcessor`).

The figures
-----------
Each evaluation also compares the current model (the recursive estimator's) with the
reference model, over the analysis band [f_lo, f_hi]:

* ``frf_db``: the RMS over the band's frequency grid of 20 log10 |H(f) / H_ref(f)|;
* ``gain_db``: 20 log10 |H(f_lo) / H_ref(f_lo)| (the DC gain when the band starts at 0);
* ``pole_shift``: |s − s_ref| / |s_ref| for the dominant pole (the pole closest to the
  unit circle, s = ln(z) / dt) among the poles whose natural frequency is in the band;
* ``test``: the CUSUM over its threshold, S/h (an alarm at 1; S is held at h at most,
  and an alarm clears once S/h stays below 1/2 for ``clear_s``).

The figures are recorded and shown; they raise no alarm unless a threshold is given
(``frf_db``, ``gain_db``, ``pole_shift``: then an alarm also needs one of them beyond
its threshold, a change worth stopping for rather than any change the test can see).

References
----------
Basseville, M. & Nikiforov, I. V. (1993) Detection of Abrupt Changes: Theory and
Application. Prentice Hall. Gustafsson, F. (2000) Adaptive Filtering and Change
Detection. Wiley. Siegmund, D. (1985) Sequential Analysis. Springer.
"""

from __future__ import annotations

import dataclasses
import math
from collections import deque
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
from scipy import linalg, optimize, stats

from ehss._settle import decay_samples
from ehss.errors import ParameterError
from ehss.identification import oe_pem
from ehss.live._kernels import prediction_errors

__all__ = ["FIGURES", "GATES", "DRIFT", "CLEAR_LEVEL", "MIN_EFFECTIVE_BLOCKS", "MAX_COEFFICIENT",
           "DetectionSettings", "Calibration", "block_statistic", "calibrate",
           "cusum_threshold", "Detector", "BaselineResidual", "output_error_predictor",
           "whitening_filter", "check_baseline",
           "dominant_pole", "figures", "TriggerSettings", "TrackingTrigger"]


@dataclass(frozen=True, kw_only=True)
class DetectionSettings:
    """How change detection decides.

    Attributes
    ----------
    compare : {"baseline", "recent"}
        Test the loop against the baseline (given, or learned over ``learn_s``), or
        against itself ``recent_s`` ago (the figures then compare with the model of
        ``recent_s`` ago; a change that lasts ``recent_s`` is learned anew).
    false_alarm_hours : float
        Mean running time between false alarms, per channel, h (default 24: one false
        alarm per channel per day of running, while the loop is the one it was while
        learning). The test's threshold follows from it (module notes).
    frf_db, gain_db, pole_shift : float
        Optional thresholds of the figures (dB, dB, fraction); ``inf`` (the default)
        leaves a figure out of the decision. With any given, an alarm needs the test and
        one of them beyond its threshold.
    clear_s : float
        How long the test must stay below half its threshold before an alarm clears
        (s).
    learn_s : float
        Stream time before detection starts: the baseline is learned over it when none
        is given, and the test is calibrated over its last three quarters.
    recent_s : float
        Look-back of ``compare="recent"`` (s).
    band_hz : (float, float) or None
        Analysis band of the figures; default the baseline model's ``band_hz``, else the
        band where the reference's spectrum is within 20 dB of its peak over the last 4 s
        of the learning time.
    """

    compare: str = "baseline"
    false_alarm_hours: float = 24.0
    frf_db: float = math.inf
    gain_db: float = math.inf
    pole_shift: float = math.inf
    clear_s: float = 2.0
    learn_s: float = 10.0
    recent_s: float = 5.0
    band_hz: tuple[float, float] | None = None

    def __post_init__(self) -> None:
        if self.compare not in ("baseline", "recent"):
            raise ParameterError(f"compare={self.compare!r} must be 'baseline' or 'recent'")
        v = self.false_alarm_hours
        if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
            raise ParameterError(f"false_alarm_hours={v!r} must be a finite time > 0 (h)")
        for name in GATES:
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and v > 0 and not math.isnan(v)):
                raise ParameterError(f"{name}={v!r} must be > 0 (inf leaves it out)")
        for name in ("clear_s", "learn_s", "recent_s"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise ParameterError(f"{name}={v!r} must be a finite time >= 0 (s)")
        if self.band_hz is not None:
            lo, hi = self.band_hz
            if not (0 <= lo < hi and math.isfinite(hi)):
                raise ParameterError(f"band_hz={self.band_hz!r} must satisfy 0 <= lo < hi")

    def to_dict(self) -> dict:
        return asdict(self)


#: Names of the figures, in the order they are recorded.
FIGURES = ("frf_db", "gain_db", "pole_shift", "test")
#: The figures that may gate an alarm with a threshold of their own.
GATES = ("frf_db", "gain_db", "pole_shift")
#: κ, the CUSUM's drift in σ: quickest for a rise of 2κ = 1 σ.
DRIFT = 0.5
#: An alarm clears when the test stays below this fraction of its threshold for
#: ``clear_s``: a change that persists holds the CUSUM near h, and the loop back to
#: normal brings it down at κ per block (h/2 in 1.2 s at the default rate); under no
#: change h/2 is reached about once per √ARL₀ blocks, rarely within ``clear_s``.
CLEAR_LEVEL = 0.5
#: A block this many σ above the learnt level belongs to the change (one block of an
#: unchanged loop in 40 lies there, under the Gaussian model): the first such block
#: since the CUSUM last was zero dates the change's start. The last zero alone (Page's
#: estimate) dates it too early whenever blocks of the unchanged loop have lifted the
#: sum above zero by its drift of 0.5 σ, one block in three.
ONSET_Z = 2.0
#: Fewest independent blocks of learning the test is calibrated from.
MIN_EFFECTIVE_BLOCKS = 5
#: One-sided z of the test that takes a rise of the statistic for a rise of the
#: reference's level (:func:`level_rose`: the compensator's trigger and the live
#: detection's alarm): 1 %, under the Gaussian model of the blocks' levels.
LEVEL_Z = 2.326
#: Largest lag-1 autocorrelation of the blocks taken into the long-run variance.
_MAX_RHO = 0.9
#: Siegmund's correction of the threshold for the overshoot of Gaussian increments.
_OVERSHOOT = 1.166

def block_statistic(eps: np.ndarray) -> float:
    """x = ln(median ε²) of one block's prediction errors; NaN for an empty block or a
    median of 0 (errors that are exactly zero: a noise-free record)."""
    if not eps.size:
        return math.nan
    med = float(np.median(np.square(eps)))
    return math.log(med) if med > 0 and math.isfinite(med) else math.nan


def cusum_threshold(arl_blocks: float, drift: float = DRIFT) -> float:
    """The threshold h of a one-sided CUSUM of N(0, 1) increments with drift κ whose
    average run length to a false alarm is ``arl_blocks`` (Siegmund's approximation,
    module notes); 0 when even h = 0 runs that long."""
    if not (math.isfinite(arl_blocks) and arl_blocks > 0):
        raise ParameterError(f"arl_blocks={arl_blocks!r} must be a finite number > 0")

    def log_arl(h: float) -> float:
        x = 2 * drift * (h + _OVERSHOOT)
        # ln((e^x − 1 − x) / (2κ²)), computed without overflow for large x
        return x + math.log(-math.expm1(-x) - x * math.exp(-x)) - math.log(2 * drift**2)

    target = math.log(arl_blocks)
    if log_arl(0.0) >= target:
        return 0.0
    hi = 1.0
    while log_arl(hi) < target:
        hi *= 2
    return float(optimize.brentq(lambda h: log_arl(h) - target, 0.0, hi, xtol=1e-9))


@dataclass(frozen=True)
class Calibration:
    """The statistics of the learning time that the test is set from.

    Attributes
    ----------
    mean, sd : float
        μ and σ of x = ln(median ε²) per block, at their 97.5 % confidence bounds.
    mean_hat, sd_hat : float
        The learning blocks' own mean and long-run standard deviation.
    n_blocks : int
        Blocks of learning used.
    n_effective : float
        Independent blocks they are worth (n s²/σ²).
    threshold : float
        h of the CUSUM (in σ).
    arl_blocks : float
        The average run length to a false alarm it is set for, in blocks.
    """

    mean: float
    sd: float
    mean_hat: float
    sd_hat: float
    n_blocks: int
    n_effective: float
    threshold: float
    arl_blocks: float

    def to_dict(self) -> dict:
        return asdict(self)


def calibrate(x: np.ndarray, *, arl_blocks: float, two_sided: bool = False) -> Calibration:
    """Calibrate the test from the learning blocks' statistics ``x`` (module notes).

    ``two_sided`` (``compare="recent"``): two CUSUMs share the rate, each set for twice
    the run length.

    Raises
    ------
    ParameterError
        If the blocks are worth fewer than :data:`MIN_EFFECTIVE_BLOCKS` independent ones,
        or do not vary (no noise at all: nothing to calibrate from).
    """
    x = np.asarray(x, dtype=np.float64)
    x = x[np.isfinite(x)]
    n = x.size
    if n < MIN_EFFECTIVE_BLOCKS:
        raise ParameterError(f"{n} blocks of learning are too few to calibrate the test "
                             f"(at least {MIN_EFFECTIVE_BLOCKS}): give a longer learn time")
    mu, s = float(np.mean(x)), float(np.std(x, ddof=1))
    if not s > 0:
        raise ParameterError("the prediction errors of the learning time do not vary: "
                             "no noise to calibrate the test from")
    d = x - mu
    # σ² = s² (1 + ρ)/(1 − ρ), ρ the lag-1 autocorrelation (AR(1) long-run variance)
    rho = min(_MAX_RHO, max(0.0, float(np.dot(d[:-1], d[1:]) / np.dot(d, d))))
    inflation = (1.0 + rho) / (1.0 - rho)
    sd_lr = s * math.sqrt(inflation)
    n_eff = n / inflation
    if n_eff < MIN_EFFECTIVE_BLOCKS:
        raise ParameterError(f"the learning time holds {n_eff:.1f} independent blocks, too "
                             f"few to calibrate the test (at least {MIN_EFFECTIVE_BLOCKS}): "
                             "give a longer learn time")
    dof = n_eff - 1.0
    # one-sided 97.5 % bounds: μ + t σ/√n_eff, σ √(dof / χ²_0.025(dof))
    mean = mu + float(stats.t.ppf(0.975, dof)) * sd_lr / math.sqrt(n_eff)
    sd = sd_lr * math.sqrt(dof / float(stats.chi2.ppf(0.025, dof)))
    arl = arl_blocks * (2.0 if two_sided else 1.0)
    return Calibration(mean=mean, sd=sd, mean_hat=mu, sd_hat=sd_lr, n_blocks=n,
                       n_effective=n_eff, threshold=cusum_threshold(arl), arl_blocks=arl)


def recentred(held: Calibration, new: Any) -> Calibration:
    """``held`` moved to a new test level's own blocks ``new`` (their statistics x),
    ``held`` while they are fewer than :data:`MIN_EFFECTIVE_BLOCKS`: its mean their
    mean at its one-sided 97.5 % bound, its σ the larger of the held one and the new
    blocks' at its 97.5 % bound (the blocks taken as independent: too few to tell
    their correlation).

    The spread can change with the level as the mean does: at half the rig's test
    level its prediction errors are mostly sensor noise and x hardly moves (σ 0.29);
    at the full level they are mostly what the model misses, which follows the
    reference, and x follows each block's level (2-3× the spread). Tested with the
    spread held, a stationary channel rose to its threshold twice within 11 s of
    doubling its test level."""
    new = np.asarray(new, dtype=np.float64)
    new = new[np.isfinite(new)]
    n = new.size
    if n < MIN_EFFECTIVE_BLOCKS:
        return held
    mu, s = float(np.mean(new)), float(np.std(new, ddof=1))
    spread = max(held.sd_hat, s)
    mean = mu + float(stats.t.ppf(0.975, n - 1)) * spread / math.sqrt(n)
    sd = max(held.sd, s * math.sqrt((n - 1) / float(stats.chi2.ppf(0.025, n - 1))))
    return dataclasses.replace(held, mean=mean, mean_hat=mu, sd=sd, sd_hat=spread)


class Detector:
    """The sequential test and alarm logic of one channel.

    Call :meth:`statistic` with each block's x = ln(median ε²) (NaN: no block), one per
    predictor the test was started with, then :meth:`step` with the figures;
    it returns ``"alarm"`` when an alarm is raised, ``"clear"`` when one
    clears, ``"level"`` when the test would alarm but the reference's level rose as
    much (:func:`level_rose`, with the levels given to :meth:`start`; the caller then
    calibrates the test anew), else None. Before :meth:`start` it decides nothing.

    With several predictors, each has its CUSUM, calibrated on its own statistics for
    its share of the false-alarm rate (:func:`calibrate` with ``arl_blocks`` times
    their number: the rate of the union is at most the one set), and the test is the
    largest S/h of them.
    """

    def __init__(self, settings: DetectionSettings) -> None:
        self.settings = settings
        self._limits = np.array([getattr(settings, g) for g in GATES])
        self._gated = bool(np.any(np.isfinite(self._limits)))
        self.calibrations: tuple[Calibration, ...] = ()
        self.active = False
        self._up = self._down = np.zeros(0)
        self._since: float | None = None
        self._past: list[list[float]] = []
        self._lag = 0
        self._clear_on_start = False
        # the learnt blocks' levels (None: no level test), and, per predictor, those of
        # the blocks since its upward sum was last zero
        self._learnt_levels: np.ndarray | None = None
        self._rising: list[list[float]] = []
        # the levels of the latest blocks (as many as were learnt, and those of a
        # rise), and per predictor the blocks since its upward sum was last zero
        self._history: deque[float] = deque()
        self._run_blocks: list[int] = []
        # at a new test level (hold_at_new_level): the calibrations of before, and
        # whether the test waits for the new level's blocks
        self._held: tuple[Calibration, ...] | None = None
        self._waiting = False

    @property
    def calibration(self) -> Calibration | None:
        """The first predictor's calibration (None before :meth:`start`)."""
        return self.calibrations[0] if self.calibrations else None

    def restart(self) -> None:
        """Stop testing until :meth:`start` with a new calibration; an alarm that is on
        clears at the first step after it."""
        self.calibrations = ()
        self._up = self._down = np.zeros(0)
        self._since = None
        self._past = []
        self._rising = []
        self._run_blocks = []
        self._held = None
        self._waiting = False
        self._clear_on_start = self.active

    def start(self, calibration: Calibration | Sequence[Calibration], *,
              lag_blocks: int = 0, levels: Any = None) -> None:
        """Start testing with ``calibration`` (one per predictor); ``lag_blocks`` > 0:
        two-sided on the statistic against its value that many blocks ago
        (``compare="recent"``); ``levels``: the levels of the reference in the blocks it
        was calibrated on (:func:`block_level`), for :meth:`step` to tell a rise of the
        test level."""
        cals = (calibration,) if isinstance(calibration, Calibration) else tuple(calibration)
        self.calibrations = cals
        self._up, self._down = np.zeros(len(cals)), np.zeros(len(cals))
        self._past = [[] for _ in cals]
        self._rising = [[] for _ in cals]
        self._run_blocks = [0 for _ in cals]
        self._held = None
        self._waiting = False
        self._lag = int(lag_blocks)
        self._learnt_levels = None if levels is None else np.asarray(levels, dtype=float)
        self._keep_history()

    def add(self, calibration: Calibration) -> None:
        """Add a predictor's test (calibrated for its share of the rate), its CUSUM
        from 0; the others go on as they were."""
        if not self.calibrations:
            raise ParameterError("a predictor joins a test that has started: call start first")
        self.calibrations = (*self.calibrations, calibration)
        self._up, self._down = np.append(self._up, 0.0), np.append(self._down, 0.0)
        self._past.append([])
        self._rising.append([])
        self._run_blocks.append(0)
        if self._held is not None:
            self._held = (*self._held, calibration)

    @property
    def started(self) -> bool:
        return bool(self.calibrations)

    def hold_at_new_level(self) -> None:
        """Go on at a new test level (after :meth:`step` said ``"level"``) until
        :meth:`start` calibrates the test there: the sums start from zero, and the test
        waits until :meth:`recentre` has :data:`MIN_EFFECTIVE_BLOCKS` of the new
        level's blocks to move the calibrations to (:func:`recentred`).

        Calibrated anew from nothing instead, the test was blind for its whole learning
        time (7.5 s by default) and took in what came meanwhile: on the simulated rig a
        +40 % payload 3 s after the test level doubled was never flagged. Tested on
        at once against the calibration of before moved up by the rise, it alarmed
        falsely within a second: the spread of the statistic grows with the level too
        (:func:`recentred`), and is not known before the new level's blocks show it."""
        if not self.calibrations:
            return
        self._held, self._waiting = self.calibrations, True
        self._up[:] = 0.0
        self._down[:] = 0.0
        self._rising = [[] for _ in self.calibrations]
        self._run_blocks = [0 for _ in self.calibrations]

    def recentre(self, x: Any, levels: Any) -> None:
        """At a new test level (:meth:`hold_at_new_level`): the calibrations of before
        moved to the new level's own blocks ``x`` (shape (blocks, predictors);
        :func:`recentred`), and the levels a further rise is judged against
        (:func:`level_rose`) to theirs, ``levels``, once there are
        :data:`MIN_EFFECTIVE_BLOCKS` of them; the test then runs again."""
        x = np.asarray(x, dtype=np.float64)
        if self._held is None or x.ndim != 2 or x.shape[0] < MIN_EFFECTIVE_BLOCKS \
                or x.shape[1] != len(self._held):
            return
        self.calibrations = tuple(recentred(cal, x[:, k])
                                  for k, cal in enumerate(self._held))
        self._learnt_levels = np.asarray(levels, dtype=np.float64)
        self._keep_history()
        self._waiting = False

    def _keep_history(self) -> None:
        """Keep the levels of as many latest blocks as were learnt, and those of the
        longest rise the test sums up to its threshold, for :meth:`_level_explains`."""
        n = 0 if self._learnt_levels is None else self._learnt_levels.size
        n += max((rise_blocks(cal.threshold) for cal in self.calibrations), default=0)
        self._history = deque(self._history, maxlen=max(1, 2 * n))

    def exceeded(self, values: np.ndarray) -> list[str]:
        """Names of the gated figures beyond their thresholds (NaN is not), and "test"
        when the test is at or beyond its threshold."""
        over = np.abs(np.asarray(values[:len(GATES)])) > self._limits
        names = [name for name, o in zip(GATES, over, strict=True) if o]
        return names + (["test"] if values[-1] >= 1.0 else [])

    def _increment(self, k: int, x: float, cal: Calibration) -> tuple[float, float] | None:
        """The standardised increments (upward, downward) of predictor ``k``'s block x,
        None when the block gives none."""
        if not math.isfinite(x):
            return None
        if self._lag == 0:
            return (x - cal.mean) / cal.sd, -math.inf
        past = self._past[k]
        past.append(x)
        if len(past) <= self._lag:
            return None
        diff = (x - past.pop(0)) / (math.sqrt(2.0) * cal.sd)
        return diff, -diff

    def statistic(self, x: float | Sequence[float] | np.ndarray,
                  level: float = math.nan) -> float:
        """Update the CUSUMs with the block's x, one per predictor (run at the
        reference's ``level``, :func:`block_level`); returns the largest S/h (the
        ``test`` figure; NaN before the test starts)."""
        if not self.calibrations:
            return math.nan
        self._history.append(level)
        if self._waiting:
            return 0.0                   # at a new test level, until recentre
        xs = np.atleast_1d(np.asarray(x, dtype=np.float64))[:len(self.calibrations)]
        # a predictor that joined since the block began gives none for it
        xs = np.concatenate((xs, np.full(len(self.calibrations) - xs.size, math.nan)))
        out = 0.0
        for k, cal in enumerate(self.calibrations):
            inc = self._increment(k, float(xs[k]), cal)
            h = cal.threshold
            if inc is not None:
                # S_k = max(0, S_{k−1} + z_k − κ), both sides; held at h at most, so that
                # it falls below h soon after the loop is back (the alarm then clears)
                self._up[k] = min(h, max(0.0, self._up[k] + inc[0] - DRIFT))
                self._down[k] = min(h, max(0.0, self._down[k] + inc[1] - DRIFT))
                # only the latest blocks of a rise are judged (level_rose): keep no more
                self._rising[k] = [*self._rising[k], level][-rise_blocks(h):] \
                    if self._up[k] > 0.0 else []
            # every block since the sum left zero, as self._history holds them
            self._run_blocks[k] = self._run_blocks[k] + 1 if self._up[k] > 0.0 else 0
            s = max(self._up[k], self._down[k])
            out = max(out, s / h if h > 0 else (1.0 if s > 0 else 0.0))
        return out

    def _level_explains(self) -> bool:
        """Whether the reference's level rose with every test at its threshold: when
        its rise began, against the blocks just before it (as many as were learnt;
        :func:`level_rose`), or against the learnt blocks while fewer than
        :data:`MIN_EFFECTIVE_BLOCKS` came before it since the test started.

        Against the learnt blocks always, a test level raised after the learning time
        without a rise of the statistic (a linear loop, whose prediction errors are its
        sensor's noise, does not raise them) explained every later rise: on the
        specimen, the delayed loop and the high-pass loop, stepped from 25 % to 50 % at
        20 s and to 100 % at 30 s, +40 % mass or stiffness at 33 s was taken for a new
        test level and never flagged."""
        if self._learnt_levels is None or self._lag != 0:
            return False
        at = [k for k, cal in enumerate(self.calibrations)
              if self._up[k] >= cal.threshold]
        return bool(at) and all(level_rose(self._levels_before(k), self._rising[k],
                                           self.calibrations[k]) for k in at)

    def _levels_before(self, k: int) -> np.ndarray:
        """The levels of the blocks before predictor ``k``'s rise began (as many as
        were learnt), or the learnt blocks' if too few of them are kept."""
        assert self._learnt_levels is not None
        history = list(self._history)
        before = history[:max(0, len(history) - self._run_blocks[k])]
        before = before[-self._learnt_levels.size:]
        if len(before) < MIN_EFFECTIVE_BLOCKS:
            return self._learnt_levels
        return np.asarray(before, dtype=np.float64)

    def step(self, t_s: float, values: np.ndarray) -> str | None:
        """Decide on the figures ``values`` (the last is ``test``, S/h) at ``t_s``."""
        if not self.calibrations:
            return None
        if self._clear_on_start:
            self._clear_on_start = False
            self.active = False
            return "clear"
        if not self.active:
            if values[-1] >= 1.0 and (not self._gated or self.exceeded(values)[:-1]):
                if self._level_explains():
                    # the reference's level rose with the statistic: a new test level
                    return "level"
                self.active, self._since = True, None
                return "alarm"
            return None
        if values[-1] >= CLEAR_LEVEL:
            self._since = None
            return None
        if self._since is None:
            self._since = t_s
        if t_s - self._since + 1e-9 >= self.settings.clear_s:
            self.active, self._since = False, None
            self._up[:] = 0.0
            self._down[:] = 0.0
            return "clear"
        return None


def _reflect_inside(c: np.ndarray) -> np.ndarray:
    """Monic C with its roots outside the unit circle reflected inside (1/z̄): the same
    spectrum up to a gain, and 1/C a stable filter. Roots on the circle are pulled in to
    radius 0.999."""
    roots = np.roots(c) if c.size > 1 else np.empty(0)
    r = np.abs(roots)
    if not roots.size or np.all(r < 0.999):
        return c
    roots = np.where(r > 1.0, 1.0 / np.conj(roots), roots)
    r = np.abs(roots)
    roots = np.where(r >= 0.999, roots * (0.999 / np.maximum(r, 1e-300)), roots)
    return np.real(np.poly(roots))


class BaselineResidual:
    """The prediction error ε = [A y − q^{-d} B u] / C of a fixed model, sample by sample
    across blocks (the filters' state carried over).

    Parameters
    ----------
    a, b, c : ndarray
        ``[1, a1, …]``, ``[b0, …]``, ``[1, c1, …]`` of the model.
    delay : int
    """

    def __init__(self, a: np.ndarray, b: np.ndarray, c: np.ndarray, delay: int) -> None:
        c = _reflect_inside(np.asarray(c, dtype=np.float64))
        bd = np.concatenate((np.zeros(delay), np.asarray(b, dtype=np.float64)))
        a = np.asarray(a, dtype=np.float64)
        m = max(a.size, bd.size, c.size)
        self._a, self._bd, self._c = (np.ascontiguousarray(np.pad(v, (0, m - v.size)))
                                      for v in (a, bd, c))
        # the last m − 1 values of y, u and ε, newest first (the filters' state); after
        # a restart, how many samples still go to the history, and how many more give
        # no error while the start dies out (7 time constants of C's slowest root)
        self._hy, self._hu, self._he = np.zeros(m - 1), np.zeros(m - 1), np.zeros(m - 1)
        radius = float(np.max(np.abs(np.roots(self._c)), initial=0.0))
        self.settle = m - 1 + decay_samples(radius)
        self._fill = self._quiet = 0

    def restart(self) -> None:
        """Forget the past: samples were lost, and the history no longer leads up to the
        samples that come. The next m − 1 samples fill the history (the past errors
        taken as 0), and the errors of the next :attr:`settle` samples are NaN (a block
        holding one gives no statistic) while that start dies out: a predictor with
        slow roots of C (an output-error one) carries it for as long as they take to
        decay."""
        self._he[:] = 0.0
        self._fill = self._hy.size
        self._quiet = self.settle

    def __call__(self, u: np.ndarray, y: np.ndarray) -> np.ndarray:
        """ε over the next samples ``u``, ``y``."""
        u = np.ascontiguousarray(u, np.float64)
        y = np.ascontiguousarray(y, np.float64)
        out = np.empty(u.size)
        if not (self._fill or self._quiet):
            prediction_errors(self._a, self._bd, self._c, u, y, self._hy, self._hu,
                              self._he, out)
            return out
        k = min(self._fill, u.size)
        if k:
            size = self._hy.size
            self._hy[:] = np.concatenate((y[:k][::-1], self._hy))[:size]
            self._hu[:] = np.concatenate((u[:k][::-1], self._hu))[:size]
            self._fill -= k
        prediction_errors(self._a, self._bd, self._c, u[k:], y[k:], self._hy, self._hu,
                          self._he, out[k:])
        q = min(self._quiet, u.size)
        if q:
            out[:q] = math.nan
            self._quiet -= q
        return out


#: Levenberg–Marquardt evaluations of the output-error refit of the baseline
#: (:func:`output_error_predictor`): the refits on the loops of the tests took 10–40,
#: a few to a hundred ms on 7.5 s of learning at 0.5–5 kHz.
OE_REFIT_NFEV = 40

#: Order of the autoregression that whitens the output errors
#: (:func:`whitening_filter`).
WHITENING_ORDER = 4


def whitening_filter(v: np.ndarray, order: int = WHITENING_ORDER) -> np.ndarray:
    """``[1, −a1, …, −a_order]``: the autoregression of ``v`` by Yule–Walker (the
    biased autocorrelation, so that the filter is minimum phase; a Toeplitz solve,
    :func:`scipy.linalg.solve_toeplitz`), so that D(q) v is close to white.

    Examples
    --------
    >>> from scipy.signal import lfilter
    >>> e = np.random.default_rng(0).standard_normal(100_000)
    >>> v = lfilter([1.0], [1.0, -0.9], e)  # AR(1), pole 0.9
    >>> np.round(whitening_filter(v, 1), 2)
    array([ 1. , -0.9])
    """
    v = np.asarray(v, dtype=np.float64)
    r = np.array([np.dot(v[:v.size - k], v[k:]) for k in range(order + 1)]) / v.size
    if not (np.all(np.isfinite(r)) and r[0] > 0):
        raise ParameterError("the output errors do not vary: nothing to whiten")
    return np.concatenate(([1.0], -linalg.solve_toeplitz(r[:order], r[1:])))


def output_error_predictor(model: Any, u: np.ndarray, y: np.ndarray) -> BaselineResidual:
    """The second predictor of the test, from the learning time's ``u``, ``y``: ε =
    D(q) [y − q^-d (B/F) u], the output errors of ``model``'s B/A refitted to them
    (:func:`ehss.identification.oe_pem`, started from ``model``'s own A and B, so that
    it fits no worse than they do, poles kept inside the unit circle), whitened by
    their autoregression D (:func:`whitening_filter`).

    It leans on the reference alone where the first (the baseline's one-step
    prediction, [A y − q^-d B u]/C) leans on the past feedback too: a baseline averaged
    from the live estimates whose C is far from its A predicts a changed loop nearly
    as well as the loop it learnt. On a 15 Hz loop with a 40 Hz oil-column mode
    (ζ 0.15) at 2 kHz, +40 % mass raised the first's statistic by 1.0–2.2 σ, this one's
    by 15–23 σ. The whitening keeps the slow wander of a refit that misses a slow mode
    (a 0.5 Hz high-pass) out of the statistic: unwhitened, it crossed the threshold
    in 10 stationary minutes (1.55 h) on one of three seeds.

    Raises
    ------
    EhssError
        If the record cannot be fitted (too short for the structure) or its output
        errors do not vary.
    """
    theta0 = np.concatenate((np.asarray(model.a)[1:], np.asarray(model.b)))
    oe = oe_pem(u, y, nf=model.na, nb=model.nb, delay=model.delay, dt=model.dt,
                max_nfev=OE_REFIT_NFEV, theta0=theta0)
    v = BaselineResidual(oe.a, oe.b, oe.a, oe.delay)(u, y)
    d = whitening_filter(v[v.size // 10:])         # past the filter's start from rest
    return BaselineResidual(np.convolve(oe.a, d), np.convolve(oe.b, d), oe.a, oe.delay)


#: Largest magnitude of a baseline's coefficient: beyond it, a float64 response of the
#: model, or the square of its prediction error, overflows.
MAX_COEFFICIENT = 1e12


def check_baseline(model: Any, name: str = "the baseline") -> None:
    """Refuse a baseline model that cannot be a running loop's reference: coefficients
    not finite or beyond ±:data:`MAX_COEFFICIENT`, or poles on or outside the unit
    circle (the loop it describes would not be running).

    Raises
    ------
    ParameterError
        With one line that names the model and what is wrong.
    """
    theta = np.concatenate((model.a, model.b, model.c))
    if not np.all(np.isfinite(theta)):
        raise ParameterError(f"{name} has coefficients that are not finite numbers: "
                             "not a model of a loop")
    big = float(np.max(np.abs(theta)))
    if big > MAX_COEFFICIENT:
        raise ParameterError(f"{name} has a coefficient of {big:.3g}, beyond ±"
                             f"{MAX_COEFFICIENT:.0e}: not a model of a loop")
    radius = float(model.max_pole_radius())
    if not radius < 1.0:
        raise ParameterError(f"{name} is unstable (largest pole radius {radius:.4g} >= 1): "
                             "a running loop's reference must be stable")


def dominant_pole(a: np.ndarray, dt: float,
                  band_hz: tuple[float, float] | None = None) -> complex:
    """The root of A(z) closest to the unit circle, mapped to s = ln(z)/dt (rad/s).

    ``a = [1, a1, …, a_na]``. With ``band_hz``, only the poles whose natural frequency
    |s|/2π lies in the band count (the data determine those); NaN when there is none.
    The upper one of a conjugate pair is returned.
    """
    z = np.roots(np.asarray(a, dtype=np.float64)).astype(complex)
    z = z[z != 0]
    if z.size == 0:
        return complex("nan")
    s = np.log(z) / dt
    if band_hz is not None:
        wn_hz = np.abs(s) / (2 * math.pi)
        keep = (wn_hz >= band_hz[0]) & (wn_hz <= band_hz[1])
        z, s = z[keep], s[keep]
        if z.size == 0:
            return complex("nan")
    si = s[np.argmax(np.abs(z))]
    return complex(si.real, abs(si.imag))


def figures(h: np.ndarray, h_ref: np.ndarray, s: complex, s_ref: complex) -> np.ndarray:
    """``[frf_db, gain_db, pole_shift]`` of a response ``h`` against ``h_ref``.

    ``h`` and ``h_ref`` are the two responses on the band's grid (first point at the
    band's lower edge); ``s``, ``s_ref`` their dominant poles.
    """
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        ratio_db = 20.0 * np.log10(np.abs(h) / np.abs(h_ref))
        frf = float(np.sqrt(np.mean(np.square(ratio_db))))
        gain = float(ratio_db[0])
        shift = abs(s - s_ref) / abs(s_ref) if abs(s_ref) > 0 else math.inf
    return np.array([frf, gain, shift])


def block_level(u: np.ndarray) -> float:
    """ln of the mean square of one block of the reference (NaN for an empty or silent
    block): the level a block of the test was run at (:func:`level_rose`)."""
    return level_of(float(np.dot(u, u)), u.size)


def level_of(sum_of_squares: float, n: int) -> float:
    """:func:`block_level` of a block given by its sum of squares and length."""
    if n <= 0:
        return math.nan
    ms = sum_of_squares / n
    return math.log(ms) if ms > 0 and math.isfinite(ms) else math.nan


def rise_blocks(threshold: float) -> int:
    """Blocks a CUSUM of threshold h and drift κ takes to flag a rise of 2 σ:
    ⌈h / (2 − κ)⌉, at least 1 (the blocks :func:`level_rose` judges)."""
    return max(1, math.ceil(threshold / (2.0 - DRIFT)))


def level_rose(learnt: Any, now: Any, cal: Calibration) -> bool:
    """Whether the reference's level rose with a rise of the test's statistic (``cal``
    its calibration): the mean of the blocks' levels ``now`` (ln mean square,
    :func:`block_level`: the blocks since the rise began, at most the last
    h / (2 − κ) of them, as many as the CUSUM takes to flag a rise of 2 σ, about what
    a doubled test level gives on the rig (ln 4 against σ of 0.63–0.77); earlier
    blocks belong to a slower rise before it, which on the
    4 kHz specimen dated a step's trigger 1.9 s back and hid the step in 19 blocks)
    lies above the mean of the ``learnt`` blocks' by more than
    :data:`LEVEL_Z` (1 %) standard errors of a mean of ``now.size`` of them (their
    standard deviation over √n: the blocks taken as independent; where they are
    correlated, in a narrow band, more than 1 % of steady levels pass; with the AR(1)
    model of :func:`calibrate` instead, the rig's step from 50 % to 100 % on seeds 1,
    2 was flagged as a change), and by more than the smallest rise of the statistic the
    CUSUM is set to flag (its drift, κ σ): a reference of one amplitude (a sine dwell),
    whose levels hardly scatter, explains no rise. Measured on steady band-limited
    references (2000 s each, 5 blocks): 1.1 % of tests pass over 0.5–20 Hz at 1 kHz,
    1.3 % over 1–40 Hz at 4 kHz, 2.2 % over 0.5–5 Hz.

    A loop's error grows with its reference: a test run stepped from 25 % to 50 % to
    100 % of its level raises ln(median e²) at each step, by about ln 4 under
    compensation (more while the step passes) and through the nonlinearity the
    baseline misses in the prediction errors of the live detection. A rise the level
    explains is a new test level, not a change of the loop.
    """
    learnt = np.asarray(learnt, dtype=np.float64)
    now = np.asarray(now, dtype=np.float64)[-rise_blocks(cal.threshold):]
    if learnt.size < MIN_EFFECTIVE_BLOCKS or not now.size or not (
            np.all(np.isfinite(learnt)) and np.all(np.isfinite(now))):
        return False
    rise = float(np.mean(now) - np.mean(learnt))
    se = float(np.std(learnt, ddof=1)) / math.sqrt(now.size)
    return rise > max(LEVEL_Z * se, DRIFT * cal.sd)


# ------------------------------------------------------------------ the quick trigger
@dataclass(frozen=True, kw_only=True)
class TriggerSettings:
    """How :class:`TrackingTrigger` decides.

    Attributes
    ----------
    block_s : float
        Length of each block of the statistic (s).
    learn_s : float
        The test is calibrated on ``learn_s`` of blocks, and starts (again, after a
        trigger) once that many are in.
    lag_s : float
        The blocks of the last ``lag_s`` are not yet in the calibration, so that a
        change does not enter the statistics it is tested against while the test
        sums it up (s).
    false_alarm_hours : float
        Mean running time between false triggers while the loop does not change (h),
        under the AR(1) Gaussian model of the blocks that :func:`calibrate` sets the
        threshold from; a stationary run measures it (README).
    """

    block_s: float = 0.1
    learn_s: float = 5.0
    lag_s: float = 1.0
    false_alarm_hours: float = 1.0

    def __post_init__(self) -> None:
        for name in ("block_s", "learn_s", "lag_s", "false_alarm_hours"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ParameterError(f"{name}={v!r} must be a finite number > 0")
        if self.learn_s < MIN_EFFECTIVE_BLOCKS * self.block_s:
            raise ParameterError(f"learn_s={self.learn_s!r} must hold at least "
                                 f"{MIN_EFFECTIVE_BLOCKS} blocks of {self.block_s} s")


def _onset_blocks(run: list[float]) -> int:
    """Blocks of ``run`` (the z since the CUSUM's last zero) from its first at or above
    :data:`ONSET_Z` on (all of them if none is)."""
    return len(run) - _first_onset(run)


def _first_onset(run: list[float]) -> int:
    """Index in ``run`` of its first z at or above :data:`ONSET_Z` (0 if none is)."""
    return next((i for i, z in enumerate(run) if z >= ONSET_Z), 0)


class TrackingTrigger:
    """A quick sequential test for a change of a compensated loop, on its own errors.

    Under compensation the tracking error (desired − feedback) is what the model
    misses; a change of the loop raises it at once, before an estimate of the loop
    can move. The statistic of each block is the module's x = ln(median e²)
    (:func:`block_statistic`), tested by the one-sided CUSUM of :class:`Detector`
    against the ``learn_s`` of blocks that end ``lag_s`` before it (:func:`calibrate`,
    at the run length that ``false_alarm_hours`` asks). A trigger restarts the
    learning; once a compensator that follows the change takes over
    (:meth:`test_on`), the test goes on against the blocks since, and otherwise the
    next trigger can come ``learn_s + lag_s`` later at the earliest. A fall
    of the error (a better compensator) is not a change; a rise from a worse
    compensator is flagged like a change of the loop, and dated (:attr:`onset_index`)
    so that the caller can tell it by its time and undo it
    (:meth:`rearm`: the test goes on against the level learnt before the rise).

    Parameters
    ----------
    fs : float
    settings : TriggerSettings, optional
    """

    def __init__(self, fs: float, settings: TriggerSettings | None = None) -> None:
        self.settings = settings if settings is not None else TriggerSettings()
        s = self.settings
        self._n_block = max(1, int(round(s.block_s * fs)))
        # the reference's samples of the current block, and ln of its mean square in
        # each block of self._x
        self._rbuf = np.empty(self._n_block)
        self._levels: list[float] = []
        self._kept_levels: list[float] = []
        #: triggers taken for a rise of the reference's level (:meth:`_level_rose`)
        self.level_rises = 0
        self._n_learn = max(MIN_EFFECTIVE_BLOCKS, int(round(s.learn_s / s.block_s)))
        self._n_lag = int(round(s.lag_s / s.block_s))
        self._arl = s.false_alarm_hours * 3600.0 / s.block_s
        self._buf = np.empty(self._n_block)
        self._fill = 0
        self._x: list[float] = []
        self._cusum = 0.0
        self._run: list[float] = []
        self.triggers = 0
        #: at the latest trigger, how long before it the change began (s), as near as
        #: the blocks tell (:data:`ONSET_Z`)
        self.onset_s = 0.0
        #: at the latest trigger, the samples taken before the first block of the
        #: change (:attr:`onset_s`)
        self.onset_index = 0
        #: at the latest trigger, the level of the error since the change, √(median
        #: e²) of its blocks (geometric mean), over the learnt level
        self.rise = 1.0
        #: at the latest trigger, whether the rise was there from the first block
        #: tested (since the test started or restarted): it began then or before, and
        #: :attr:`onset_index` is only the latest it can have begun
        self.onset_censored = False
        self._tested = 0
        self._seen = 0
        # what the latest trigger was tested against: the blocks before the change it
        # flagged and their calibration (kept for rearm); while the blocks are too few
        # again for a calibration of their own, the one held; no block starting before
        # sample _hold_until is tested or learnt
        self._kept: list[float] = []
        self._flagged: Calibration | None = None
        self._held: Calibration | None = None
        # while a calibration moved up to a new test level is held: the learnt blocks'
        # levels moved up as well (:meth:`_test_on_at`)
        self._held_levels: list[float] | None = None
        self._hold_until = 0
        # learning anew after a trigger (:meth:`test_on`), and whether, while it
        # learns, the blocks since :meth:`test_on` alone are tested against
        self._after_trigger = False
        self._own_only = False

    def restart(self, hold: int = 0) -> None:
        """Learn anew (the loop changed, or the first compensator takes over): the
        test waits ``learn_s`` of blocks; the next ``hold`` samples are neither tested
        nor learnt."""
        self._x = []
        self._levels = []
        self._cusum = 0.0
        self._run = []
        self._held = None
        self._held_levels = None
        self._after_trigger = self._own_only = False
        self._tested = 0
        self._hold_until = max(self._hold_until, self._seen + max(0, int(hold)))

    def test_on(self, hold: int) -> None:
        """A compensator that follows the change just flagged takes over in ``hold``
        samples: while the test learns anew (``learn_s + lag_s``), test on against
        the blocks from then on, once :data:`MIN_EFFECTIVE_BLOCKS` of them are past
        ``lag_s`` (their mean at its 97.5 % bound, with the spread learnt before the
        change: :meth:`_calibration`). Only the first call after a trigger acts.

        Learning from nothing instead, the test was blind for ``learn_s + lag_s``
        after a trigger: on the compensated rig a trigger 5 s before the test level
        doubled and 5.1 s before +40 % payload left that change unflagged, and
        channel 1 at 4–6× the level of the rig with that payload from the start over
        the 2 s after it. Testing on from the trigger itself, the change's own rise
        while the first models come flagged it anew twice, each time restarting
        their following."""
        if not self._after_trigger:
            return
        cal = self._flagged
        # the reference's levels before the change (the test begins only once the
        # blocks since outnumber MIN_EFFECTIVE_BLOCKS: a rise is judged on theirs)
        levels = self._kept_levels[-self._n_learn:]
        self.restart(hold)
        self._held, self._held_levels, self._own_only = cal, levels, True

    def rearm(self, hold: int) -> None:
        """Test on as before the latest trigger, whose rise was not a change of the
        loop and is being undone: against the blocks learnt before the change it
        flagged (those since are forgotten) and their calibration, held until new
        blocks make up the learning time again; the next ``hold`` samples (the undoing
        fading in) are neither tested nor learnt. A change still there after them is
        flagged within a few blocks (two for a rise of 7 standard deviations)."""
        self._x = list(self._kept)
        self._levels = list(self._kept_levels)
        self._held = self._flagged
        self._held_levels = None
        self._after_trigger = False   # a load's rise undone: no change to test on after
        self._cusum = 0.0
        self._run = []
        self._tested = 0
        self._hold_until = self._seen + max(0, int(hold))

    @property
    def held(self) -> bool:
        """True while the test runs on a calibration held by :meth:`rearm`."""
        return self._held is not None and self._held_levels is None

    def __call__(self, error: np.ndarray, reference: np.ndarray | None = None) -> bool:
        """Take the next samples of the tracking error (and of the desired reference
        they belong to, if given: :meth:`_level_rose`); True if a change is flagged in
        them (the test then restarts)."""
        flagged = False
        i = 0
        while i < error.size:
            take = min(self._n_block - self._fill, error.size - i)
            self._buf[self._fill:self._fill + take] = error[i:i + take]
            if reference is not None:
                self._rbuf[self._fill:self._fill + take] = reference[i:i + take]
            self._fill += take
            self._seen += take
            i += take
            if self._fill == self._n_block:
                self._fill = 0
                level = math.nan if reference is None else block_level(self._rbuf)
                if self._seen - self._n_block >= self._hold_until:
                    flagged |= self._block(block_statistic(self._buf), level)
        return flagged

    def _calibration(self) -> Calibration | None:
        """What a block is tested against: the ``learn_s`` of blocks ``lag_s`` before
        it (None while they are too few, unless a calibration is held)."""
        if len(self._x) < self._n_learn + self._n_lag:
            new = self._x[:max(0, len(self._x) - self._n_lag)]
            held = self._held
            if held is None or self._held_levels is None or len(new) < MIN_EFFECTIVE_BLOCKS:
                return None if self._own_only else held
            # at a new test level: its own blocks' mean (at its 97.5 % bound, with the
            # long-run spread held), once there are enough of them. The live Detector
            # takes the spread anew as well (recentred): its prediction errors' spread
            # grows with the level. Here that bound, wide on a few blocks, left a 4x
            # rise of the error 3 s after a 4x rise of the reference unflagged
            # (test_detect_trigger.py); the compensated rig's trigger raised nothing
            # with the spread held after its level doubled (seeds 1, 3)
            mu = float(np.mean(new))
            bound = float(stats.t.ppf(0.975, len(new) - 1)) * held.sd_hat / math.sqrt(len(new))
            return dataclasses.replace(held, mean=mu + bound, mean_hat=mu)
        self._held = self._held_levels = None
        try:
            return calibrate(np.array(self._x[:self._n_learn]), arl_blocks=self._arl)
        except ParameterError:  # blocks that do not vary: nothing to test against
            return None

    def _block(self, x: float, level: float = math.nan) -> bool:
        """Test one block's statistic against the blocks before it, then learn it (with
        ``level``, ln of the reference's mean square over the block)."""
        if not math.isfinite(x):
            return False
        cal = self._calibration()
        if cal is not None and self._test(x, cal, level):
            return True
        if len(self._x) >= self._n_learn + self._n_lag:
            self._x.pop(0)
            self._levels.pop(0)
        self._x.append(x)
        self._levels.append(level)
        return False

    def _level_rose(self, n_onset: int, level: float, cal: Calibration) -> bool:
        """Whether the rise the CUSUM just flagged is the reference's own
        (:func:`level_rose`), over the ``n_onset`` blocks since it began (the latest,
        of ``level``, not yet learnt) against the learnt blocks.

        The rig flagged 7 of 8 channel-steps of a test run stepped from 25 % to 50 % to
        100 % as changes of the loop, 0.4–1.1 s after them. Such a rise is taken for a
        new test level: the test learns anew there, as after a trigger, and nothing is
        flagged; meanwhile it tests on at the new level (:meth:`_test_on_at`). A change
        of the loop at the very moment the reference rises is not flagged either; the
        models follow it. Only a trigger is tested, so a run that triggers nowhere
        keeps its course. While a calibration moved to a new level is held, the levels
        judged against are its own blocks' once there are
        :data:`MIN_EFFECTIVE_BLOCKS` of them, before that the levels learnt before,
        moved up by the level's rise."""
        return level_rose(*self._judged_levels(n_onset, level), cal)

    def _judged_levels(self, n_onset: int, level: float) -> tuple[list[float], list[float]]:
        """The levels a rise over ``n_onset`` blocks is judged on (:meth:`_level_rose`):
        the learnt blocks' (those held, moved up to a new test level, while its own
        are fewer than :data:`MIN_EFFECTIVE_BLOCKS`), and the blocks' since the rise
        began, the latest of ``level`` (not yet learnt)."""
        learnt = self._levels[:min(self._n_learn, len(self._levels))]
        if self._held_levels is not None and len(learnt) < MIN_EFFECTIVE_BLOCKS:
            learnt = self._held_levels
        recent = self._levels[max(0, len(self._levels) - (n_onset - 1)):] \
            if n_onset > 1 else []
        return learnt, [*recent, level]

    def _test_on_at(self, n_onset: int, level: float, cal: Calibration) -> None:
        """Learn anew at the reference's new level, and meanwhile test on against
        ``cal`` moved up by the rise of the statistic that the level explained (the
        mean of the blocks :func:`level_rose` judged; :meth:`_calibration` moves it to
        the new level's own blocks as they come), with the learnt blocks' levels moved
        up by the level's own rise for the next :meth:`_level_rose`.

        Learning from nothing instead, the test was blind for ``learn_s + lag_s``: on
        the oil-column loop, a load's rise of the error that came with a rise of the
        reference's level 4.6 s before a +40 % mass hid the change, and the first 2 s
        after it were at 19.7× the level before (README)."""
        last = rise_blocks(cal.threshold)   # the blocks level_rose judges
        judged = self._run[-n_onset:][-last:]
        learnt, now = self._judged_levels(n_onset, level)
        lift = float(np.mean(now[-last:]) - np.mean(learnt))
        moved = dataclasses.replace(cal, mean=cal.mean + cal.sd * float(np.mean(judged)))
        levels = [v + lift for v in learnt]
        self.restart()
        self._held, self._held_levels = moved, levels

    def _test(self, x: float, cal: Calibration, level: float = math.nan) -> bool:
        """One step of the CUSUM; True (dated, and the test restarted) at a trigger,
        unless the reference's level rose as much (:meth:`_level_rose`: the test then
        learns anew at the new level)."""
        # S_k = max(0, S_{k−1} + z_k − κ), alarm at S_k ≥ h
        z = (x - cal.mean) / cal.sd
        self._tested += 1
        self._cusum = max(0.0, self._cusum + z - DRIFT)
        # the z of the blocks since the sum last was zero
        self._run = self._run + [z] if self._cusum > 0.0 else []
        if self._cusum < cal.threshold:
            return False
        n_onset = _onset_blocks(self._run)
        if self._level_rose(n_onset, level, cal):
            self.level_rises += 1
            self._test_on_at(n_onset, level, cal)
            return False
        self.triggers += 1
        self.onset_censored = len(self._run) == self._tested and _first_onset(self._run) == 0
        self.onset_s = n_onset * self.settings.block_s
        self.onset_index = self._seen - n_onset * self._n_block
        # x = ln(median e²): half the mean excess of x is the log of the level's ratio
        self.rise = math.exp(0.5 * cal.sd * float(np.mean(self._run[-n_onset:])))
        # the blocks before the change (this one is not among them yet)
        self._kept = self._x[:max(0, len(self._x) - (n_onset - 1))]
        self._kept_levels = self._levels[:len(self._kept)]
        self._flagged = cal
        self.restart()
        self._after_trigger = True
        return True
