"""Records that stand out from a campaign's own spread, with why.

For each channel and each figure (:data:`ehss.campaign.figures.FIGURES`), in record-time
order, the figure's slow course is followed by a running median over ``window`` records
of its neighbours (so that a slow drift — oil that ages, a seal that wears — is a trend,
not a string of outliers), and each record's residual from it is scored robustly:

.. math::

    z_i = \\frac{r_i - \\operatorname{median}(r)}{1.4826\\,\\operatorname{MAD}(r)}

(1.4826 MAD estimates the standard deviation of normal residuals, unaffected by the
outliers themselves). A record is flagged when ``|z| > Φ⁻¹(1 − α / (2 m))`` for one of
the ``m`` figures: under normal residuals each figure's two-sided false-flag rate is
α/m and, by Bonferroni, the chance that a sound record is flagged for any figure is at
most α (default 0.1 %: about one false flag in three years of daily records on one
channel).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["MIN_RECORDS", "OutlierRule", "robust_z", "running_median", "flag_outliers"]

#: Fewest records with a value for a figure to be scored (a MAD of fewer says little).
MIN_RECORDS = 10
_MAD_TO_SIGMA = 1.4826  # 1 / Φ⁻¹(3/4): MAD of a normal sample × this ≈ its σ


@dataclass(frozen=True, kw_only=True)
class OutlierRule:
    """How records are flagged.

    Attributes
    ----------
    alpha : float, default 0.001
        Family-wise false-flag rate per record and channel under normal residuals
        (about one false flag in three years of daily records on one channel).
    window : int, default 15
        Records in the running median that follows a figure's slow course; a campaign
        shorter than twice this is scored about its plain median.
    """

    alpha: float = 0.001
    window: int = 15

    def __post_init__(self) -> None:
        from ehss._checks import check_int, check_real

        check_real(self.alpha, "alpha", lo=0.0, hi=1.0, lo_open=True, hi_open=True)
        check_int(self.window, "window", lo=3)

    def threshold(self, n_figures: int) -> float:
        """|z| beyond which a figure flags a record: Φ⁻¹(1 − α/(2m))."""
        from scipy.stats import norm

        return float(norm.isf(self.alpha / (2.0 * max(n_figures, 1))))


def running_median(x: np.ndarray, window: int) -> np.ndarray:
    """Running median of each point's ``window - 1`` neighbours (half on each side,
    fewer at the ends; the point itself left out, so that an outlier cannot pull its
    own trend), NaNs ignored."""
    n = x.size
    half = window // 2
    out = np.full(n, math.nan)
    for i in range(n):
        seg = np.concatenate([x[max(0, i - half): i], x[i + 1: i + half + 1]])
        seg = seg[np.isfinite(seg)]
        if seg.size:
            out[i] = float(np.median(seg))
    return out


def robust_z(x: np.ndarray, window: int) -> tuple[np.ndarray, np.ndarray, float]:
    """Robust z-scores of ``x`` (in record order) about its running median.

    Returns
    -------
    z : ndarray
        NaN where ``x`` is NaN, and everywhere when the residuals' MAD is 0 or fewer
        than :data:`MIN_RECORDS` values are finite.
    trend : ndarray
        The running median (the plain median when ``x`` has fewer than ``2·window``
        finite values).
    sigma : float
        1.4826 × MAD of the residuals.
    """
    x = np.asarray(x, dtype=np.float64)
    finite = np.isfinite(x)
    if finite.sum() >= 2 * window:
        trend = running_median(x, window)
    else:
        trend = np.full(x.size, float(np.median(x[finite])) if finite.any() else math.nan)
    r = x - trend
    rf = r[np.isfinite(r)]
    if rf.size < MIN_RECORDS:
        return np.full(x.size, math.nan), trend, math.nan
    center = float(np.median(rf))
    sigma = _MAD_TO_SIGMA * float(np.median(np.abs(rf - center)))
    if not sigma > 0:
        return np.full(x.size, math.nan), trend, sigma
    return (r - center) / sigma, trend, sigma


def flag_outliers(values: dict[str, np.ndarray], rule: OutlierRule
                  ) -> tuple[np.ndarray, list[str], dict[str, np.ndarray]]:
    """Flag the records of one channel (arrays in record-time order, one per figure).

    Returns
    -------
    flagged : ndarray of bool
    reasons : list of str
        Per record, why it is flagged ("" if not): each figure beyond the threshold
        with its value, the trend and z.
    z : dict of str to ndarray
        The z-scores per figure.
    """
    names = list(values)
    n = len(next(iter(values.values()))) if values else 0
    c = rule.threshold(len(names))
    flagged = np.zeros(n, dtype=bool)
    reasons: list[list[str]] = [[] for _ in range(n)]
    zs = {}
    for name in names:
        z, trend, _ = robust_z(values[name], rule.window)
        zs[name] = z
        for i in np.flatnonzero(np.abs(np.nan_to_num(z)) > c):
            flagged[i] = True
            reasons[i].append(f"{name} {values[name][i]:.4g} vs trend {trend[i]:.4g} "
                              f"(z = {z[i]:+.1f}, |z| > {c:.2f})")
    return flagged, ["; ".join(r) for r in reasons], zs
