"""Change detection: figures that compare the current model with a reference model,
and alarms raised when they stay beyond their thresholds.

Three figures, each computed from the two models' frequency responses and poles over
the analysis band [f_lo, f_hi]:

* ``frf_db``: the RMS over the band's frequency grid of 20 log10 |H(f) / H_ref(f)|,
  the distance of the two responses in dB;
* ``gain_db``: 20 log10 |H(f_lo) / H_ref(f_lo)|, the gain change at the band's lower
  edge (the DC gain when the band starts at 0);
* ``pole_shift``: |s − s_ref| / |s_ref| for the dominant pole (the pole closest to the
  unit circle, the slowest mode, in continuous time s = ln(z) / dt) among the poles
  whose natural frequency lies in the band: a pole outside it is hardly determined by
  the data, and its relative shift means little.

An alarm is raised when any figure stays beyond its threshold for ``hold_s`` of stream
time, and cleared when all of them stay below for ``clear_s``. A figure that cannot be
computed (NaN: e.g. no pole in the band) raises nothing.

The default hold follows the estimator: 1.5 times its memory 1/((1 − λ) fs). Its
estimates are correlated over about one memory, so an excursion of the estimate under
noise leaves a threshold for about that long, while a change of the loop stays.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, replace

import numpy as np

from ehss.errors import ParameterError

__all__ = ["FIGURES", "HOLD_MEMORIES", "MIN_HOLD_S", "DetectionSettings", "Detector",
           "dominant_pole", "figures"]

#: Names of the figures, in the order they are recorded.
FIGURES = ("frf_db", "gain_db", "pole_shift")
#: The default hold, in memories of the estimator (:meth:`DetectionSettings.for_memory`).
HOLD_MEMORIES = 1.5
#: The shortest default hold (s): two evaluations at the default 0.1 s interval.
MIN_HOLD_S = 0.2


@dataclass(frozen=True, kw_only=True)
class DetectionSettings:
    """Thresholds and times of change detection.

    Attributes
    ----------
    compare : {"baseline", "recent"}
        Compare with the baseline model (given, or identified over the first
        ``learn_s``) or with the model of ``recent_s`` ago.
    frf_db, gain_db, pole_shift : float
        Thresholds of the figures (dB, dB, fraction); ``inf`` disables one. The default
        0.5 dB is half the 1 dB a validated model may differ from the H1 estimate; each
        threshold should sit well above the figure's stationary spread (shown as the
        peak figure by the summary and recorded with every evaluation). The pole shift
        is computed and recorded but raises no alarm by default: a model of this order
        places its dominant in-band pole poorly when the loop's main dynamics lie near
        the band's edges (e.g. 0.1 turns it on).
    hold_s : float or None
        How long a figure must stay beyond its threshold before the alarm (s). None
        (the default): :data:`HOLD_MEMORIES` times the estimator's memory, at least
        :data:`MIN_HOLD_S` and at most ``learn_s`` (:meth:`for_memory`; 0.45 s for the
        default 0.3 s memory).
    clear_s : float
        How long all figures must stay below before the alarm clears (s).
    learn_s : float
        Stream time before detection starts (the baseline is identified over it when
        none is given).
    recent_s : float
        Look-back of ``compare="recent"`` (s).
    band_hz : (float, float) or None
        Analysis band; default the baseline model's ``band_hz``, else the band where
        the reference's spectrum is within 20 dB of its peak over the last 4 s of the
        learning time.
    """

    compare: str = "baseline"
    frf_db: float = 0.5
    gain_db: float = 1.0
    pole_shift: float = math.inf
    hold_s: float | None = None
    clear_s: float = 2.0
    learn_s: float = 10.0
    recent_s: float = 5.0
    band_hz: tuple[float, float] | None = None

    def __post_init__(self) -> None:
        if self.compare not in ("baseline", "recent"):
            raise ParameterError(f"compare={self.compare!r} must be 'baseline' or 'recent'")
        for name in ("frf_db", "gain_db", "pole_shift"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and v > 0 and not math.isnan(v)):
                raise ParameterError(f"{name}={v!r} must be > 0 (inf disables it)")
        for name in ("hold_s", "clear_s", "learn_s", "recent_s"):
            v = getattr(self, name)
            if name == "hold_s" and v is None:
                continue
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise ParameterError(f"{name}={v!r} must be a finite time >= 0 (s)")
        if self.band_hz is not None:
            lo, hi = self.band_hz
            if not (0 <= lo < hi and math.isfinite(hi)):
                raise ParameterError(f"band_hz={self.band_hz!r} must satisfy 0 <= lo < hi")

    def to_dict(self) -> dict:
        return asdict(self)

    def for_memory(self, memory_s: float) -> DetectionSettings:
        """These settings with the default hold set for an estimator of memory
        ``memory_s`` (s; ``inf`` without forgetting): :data:`HOLD_MEMORIES` memories, at
        least :data:`MIN_HOLD_S`, at most ``learn_s``. A hold already given is kept."""
        if self.hold_s is not None:
            return self
        hold = min(max(MIN_HOLD_S, HOLD_MEMORIES * memory_s), max(MIN_HOLD_S, self.learn_s))
        return replace(self, hold_s=hold)


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
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio_db = 20.0 * np.log10(np.abs(h) / np.abs(h_ref))
        frf = float(np.sqrt(np.mean(np.square(ratio_db))))
        gain = float(ratio_db[0])
        shift = abs(s - s_ref) / abs(s_ref) if abs(s_ref) > 0 else math.inf
    return np.array([frf, gain, shift])


class Detector:
    """Hold-time alarm logic of one channel.

    Call :meth:`step` with each new set of figures; it returns ``"alarm"`` when an
    alarm is raised, ``"clear"`` when one clears, else None.
    """

    def __init__(self, settings: DetectionSettings) -> None:
        if settings.hold_s is None:
            raise ParameterError("the hold time is not set: give hold_s, or take the "
                                 "estimator's default with DetectionSettings.for_memory")
        self.settings = settings
        self._limits = np.array([settings.frf_db, settings.gain_db, settings.pole_shift])
        self.active = False
        self._since: float | None = None

    def exceeded(self, values: np.ndarray) -> list[str]:
        """Names of the figures beyond their thresholds (NaN is not)."""
        over = np.abs(values) > self._limits
        return [name for name, o in zip(FIGURES, over, strict=True) if o]

    def step(self, t_s: float, values: np.ndarray) -> str | None:
        over = bool(self.exceeded(values))
        if over != (not self.active):
            self._since = None          # the condition to change state does not hold
            return None
        if self._since is None:
            self._since = t_s
        wait = self.settings.hold_s if not self.active else self.settings.clear_s
        if t_s - self._since + 1e-9 >= wait:
            self.active = not self.active
            self._since = None
            return "alarm" if self.active else "clear"
        return None
