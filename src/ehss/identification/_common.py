"""What every estimator of the identification package shares: settings, scaling, regressors.

The orders and settings of the estimators as checked frozen objects (:class:`ArmaxOrders`,
:class:`RelsSettings`, and the keyword forms the public functions take), the RMS scaling
of a record (and the factor that carries θ between scaled and physical units), the
regression matrix ψ(k)ᵀ = [−y(k−1)..−y(k−na), u(k−d)..u(k−d−nb), e(k−1)..e(k−nc)] of the
paper's eq. (19), the one-step prediction errors ε = (A y − q^-d B u)/C of a θ, the
reflection of a monic polynomial's roots into a circle, and the state of the compiled
RELS/RML loop (its start, its counters, its estimate as a model). Batch (least squares,
ELS, PEM) and recursive (RELS, RML) estimators use these one definitions.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, TypedDict

import numpy as np
from scipy.signal import lfilter

from ehss._checks import as_record, check_choice, check_int, check_real, show
from ehss.errors import DataError, IdentificationError, ParameterError
from ehss.identification import _kernels as _k
from ehss.identification.model import ArmaxModel, real_array

__all__ = [
    "OrderKeywords",
    "RecursionKeywords",
    "RelsKeywords",
    "ArmaxOrders",
    "RelsSettings",
    "RELS_METHODS",
    "rels_settings",
    "check_batch",
    "check_theta0",
    "solver_budget",
    "root_radius",
    "too_short",
    "first_sample",
    "record_scales",
    "rms_scale",
    "theta_scale",
    "regression_matrix",
    "prediction_errors",
    "stabilise",
    "new_state",
    "block_counters",
    "start_state",
    "model_from_state",
]


class OrderKeywords(TypedDict, total=False):
    """The keyword form of :class:`ArmaxOrders` (``na=2, nb=1, nc=1, delay=1, dt=1e-3``).

    All optional for the type checker, so that a function may take either these or a
    settings object; the object says at run time which are missing (TypeError).
    """

    na: int
    nb: int
    nc: int
    delay: int
    dt: float


class RecursionKeywords(OrderKeywords, total=False):
    """:class:`OrderKeywords` and the start of a recursion: λ, α and α_c."""

    forgetting: float
    p0: float
    p0_c: float | None


class RelsKeywords(RecursionKeywords, total=False):
    """The keyword form of :class:`RelsSettings`."""

    trace_bound: float | None
    c_radius: float
    method: str


@dataclass(frozen=True, kw_only=True)
class ArmaxOrders:
    """Orders of an ARMAX model A y = q^-d B u + C e and its sample period, checked.

    ``na`` ≥ 1, ``nb`` ≥ 0 (nb + 1 coefficients of B), ``nc`` ≥ 0, ``delay`` d ≥ 0
    samples and ``dt`` > 0 s. A wrong type raises TypeError, a wrong value
    ParameterError (:mod:`ehss._checks`); the fields hold plain Python ints and floats.
    """

    na: int
    nb: int
    nc: int
    delay: int = 1
    dt: float = 1.0

    def __post_init__(self) -> None:
        for name, lowest in (("na", 1), ("nb", 0), ("nc", 0), ("delay", 0)):
            _settle(self, name, check_int(getattr(self, name), name, lo=lowest))
        _settle(self, "dt", check_real(self.dt, "dt", lo=0.0, lo_open=True, unit="s"))

    @property
    def n_params(self) -> int:
        """Length of θ = [a1..a_na, b0..b_nb, c1..c_nc]."""
        return self.na + self.nb + 1 + self.nc

    @property
    def first_sample(self) -> int:
        """k0 = max(na, nb + d, nc): the first sample whose regressors are all measured."""
        return first_sample(self.na, self.nb, self.nc, self.delay)


RELS_METHODS = ("rels", "rml")


@dataclass(frozen=True, kw_only=True)
class RelsSettings(ArmaxOrders):
    """Orders and settings of a RELS or RML estimator (paper eqs 19–22), checked once.

    The batch :func:`~ehss.identification.rels`, the streaming
    :class:`~ehss.identification.RelsEstimator` and the many-channel forms of
    :mod:`ehss.identification.bank` all take these.

    Parameters
    ----------
    na, nb, nc, delay, dt
        As in :class:`ArmaxOrders`.
    forgetting : float
        λ in (0, 1].
    p0 : float
        α > 0 of P(0) = α I (a- and b-part).
    p0_c : float, optional
        α_c > 0 of the c-part of P(0); None: ``p0``.
    trace_bound : float, optional
        Upper bound > 0 of tr P; None: tr P(0).
    c_radius : float
        Roots of C are kept inside this radius, in (0, 1].
    method : {"rels", "rml"}
        The paper's RELS or recursive maximum likelihood.
    """

    forgetting: float = 1.0
    p0: float = 1e6
    p0_c: float | None = None
    trace_bound: float | None = None
    c_radius: float = 0.99
    method: str = "rels"

    def __post_init__(self) -> None:
        super().__post_init__()
        _settle(self, "forgetting", check_real(self.forgetting, "forgetting", lo=0.0, hi=1.0,
                                               lo_open=True))
        _settle(self, "p0", check_real(self.p0, "p0", lo=0.0, lo_open=True))
        for name in ("p0_c", "trace_bound"):  # None: follow from p0 (properties below)
            if getattr(self, name) is not None:
                _settle(self, name, check_real(getattr(self, name), name, lo=0.0, lo_open=True))
        _settle(self, "c_radius", check_real(self.c_radius, "c_radius", lo=0.0, hi=1.0,
                                             lo_open=True))
        check_choice(self.method, "method", RELS_METHODS)

    @property
    def alpha_c(self) -> float:
        """α_c of the c-part of P(0): ``p0_c``, or ``p0`` when it is None."""
        return self.p0 if self.p0_c is None else self.p0_c

    @property
    def trace_max(self) -> float:
        """The bound of tr P: ``trace_bound``, or tr P(0) when it is None."""
        if self.trace_bound is not None:
            return self.trace_bound
        return (self.na + self.nb + 1) * self.p0 + self.nc * self.alpha_c

    def meta(self, passes: int | None = None) -> dict[str, Any]:
        """The settings an estimate records in its ``meta``: λ, P(0) (α_c as used), the
        batch run's ``passes`` over the record when given, the bound of tr P as used
        and the radius of C."""
        head = {"forgetting": self.forgetting, "p0": self.p0, "p0_c": self.alpha_c}
        runs = {} if passes is None else {"passes": passes}
        return {**head, **runs, "trace_bound": self.trace_max, "c_radius": self.c_radius}

    def kernel(self, *, u_scale: float = 1.0, y_scale: float = 1.0,
               enabled: bool = True) -> _k.RelsSettings:
        """The compiled loop's settings, as plain Python scalars (one compiled signature)."""
        return _k.RelsSettings(
            na=self.na, nb=self.nb, nc=self.nc, delay=self.delay, lam=self.forgetting,
            alpha=self.p0, alpha_c=self.alpha_c, trace_max=self.trace_max,
            c_radius=self.c_radius, rml=bool(self.method == "rml" and self.nc > 0),
            enabled=bool(enabled), u_scale=float(u_scale), y_scale=float(y_scale),
        )


def rels_settings(settings: RelsSettings | None, keywords: RelsKeywords) -> RelsSettings:
    """``settings``, or the :class:`RelsSettings` of ``keywords``: one of them, not both."""
    if settings is None:
        return RelsSettings(**keywords)
    if keywords:
        raise TypeError(f"give settings= or the keywords ({', '.join(keywords)}), not both")
    if not isinstance(settings, RelsSettings):
        raise TypeError(f"settings={show(settings)} must be a RelsSettings, "
                        f"not {type(settings).__name__}")
    return settings


def solver_budget(iterations: Any, name: str, tol: Any) -> tuple[int, float]:
    """An iterative fit's budget: ``iterations`` ≥ 1 (shown as ``name``) and ``tol`` ≥ 0."""
    return check_int(iterations, name, lo=1), check_real(tol, "tol", lo=0.0)


def root_radius(radius: Any, name: str = "radius") -> float:
    """A bound of the roots of a predictor's polynomial, in (0, 1)."""
    return check_real(radius, name, lo=0.0, hi=1.0, lo_open=True, hi_open=True)


def start_radius(radius: float) -> float:
    """The radius a start's roots are stabilised to before a minimisation whose roots
    must stay inside ``radius``: that of modes 5 % faster than the slowest allowed
    (``radius ** 1.05``), so that a start on the bound begins strictly inside it, and a
    start well within it is kept as it is.

    A fixed share of the radius (0.95 of it) shrinks every mode whose time constant is
    longer than 20 samples, which a loop sampled 50 times faster than its bandwidth has:
    the recursive estimate of a 15 Hz loop at 2 kHz (poles at 0.97–0.98), given as a
    start to refine, began its output-error refit at a fit of 45 % instead of its own
    98 %, and the ARX and Steiglitz–McBride starts of the same loop, shrunk alike,
    reached it within 15 evaluations on one window of four."""
    return float(radius) ** 1.05


def check_theta0(theta0: Any, n: int) -> np.ndarray:
    """A start θ0 of n finite coefficients as a new float64 array (zeros for None).

    Raises
    ------
    TypeError
        If it does not hold real numbers.
    ParameterError
        If it is not of shape (n,) or not finite.
    """
    if theta0 is None:
        return np.zeros(n)
    t = real_array(theta0, "theta0")
    if t.shape != (n,):
        raise ParameterError(f"theta0 has shape {t.shape}, must be ({n},) = na + nb + 1 + nc")
    if not np.all(np.isfinite(t)):
        raise ParameterError(f"theta0={theta0!r} must be finite")
    return t


def _settle(obj: object, name: str, value: Any) -> None:
    """Store the checked ``value`` in a frozen dataclass's field ``name``."""
    object.__setattr__(obj, name, value)


def first_sample(na: int, nb: int, nc: int, delay: int) -> int:
    """k0 = max(na, nb + d, nc): the first sample whose regressors are all measured."""
    return max(na, nb + delay, nc)


def too_short(n_samples: int, orders: ArmaxOrders) -> None:
    """DataError when a record of ``n_samples`` cannot fit ``orders``: it needs k0 + n + 1
    samples (k0 to fill the regressors, one more than the parameters to fit them)."""
    o = orders
    need = o.first_sample + o.n_params + 1
    if n_samples < need:
        raise DataError(
            f"{n_samples} samples are too few for na={o.na}, nb={o.nb}, nc={o.nc}, "
            f"delay={o.delay}: need at least {need}"
        )


def check_batch(u: Any, y: Any, orders: ArmaxOrders) -> tuple[np.ndarray, np.ndarray]:
    """Record of a batch estimator, contiguous float64; DataError when it is bad or too
    short for ``orders``."""
    u, y = as_record(u, y)
    too_short(u.size, orders)
    return u, y


def record_scales(u: np.ndarray, y: np.ndarray, orders: ArmaxOrders,
                  where: str = "") -> tuple[float, float, np.ndarray]:
    """RMS of u and y, and the factor D of θ_physical = D θ_scaled that they make.

    Raises
    ------
    DataError
        If u and y are so far apart in magnitude that D leaves float64 (``where``, e.g.
        ``"channel 2: "``, starts the message).
    """
    o = orders
    su, sy = rms_scale(u), rms_scale(y)
    dvec = theta_scale(o.na, o.nb, o.nc, su, sy)
    if not np.all((dvec >= np.finfo(float).tiny) & np.isfinite(dvec)):
        raise DataError(
            f"{where}u and y are too far apart in magnitude for float64 (RMS of u {su:.3g}, "
            f"of y {sy:.3g}: b would be scaled by {sy:.3g}/{su:.3g}); rescale them"
        )
    return su, sy, dvec


def rms_scale(x: np.ndarray) -> float:
    """RMS of x, formed as max|x| · RMS(x / max|x|) so that it neither overflows nor
    underflows for data of any float64 magnitude (1 for an all-zero record)."""
    peak = float(np.max(np.abs(x))) if x.size else 0.0
    if not (peak > 0.0 and math.isfinite(peak)):
        return 1.0
    return peak * float(np.sqrt(np.mean(np.square(x / peak))))


def theta_scale(na: int, nb: int, nc: int, u_scale: float, y_scale: float) -> np.ndarray:
    """Factor D with θ_physical = D θ_scaled (only the b-part changes: b = b_s s_y/s_u)."""
    dvec = np.ones(na + nb + 1 + nc)
    with np.errstate(over="ignore", under="ignore"):  # the caller checks the product
        dvec[na : na + nb + 1] = y_scale / u_scale
    return dvec


def regression_matrix(
    u: np.ndarray, y: np.ndarray, e: np.ndarray | None, na: int, nb: int, nc: int, delay: int
) -> tuple[np.ndarray, np.ndarray, int]:
    """Rows ψ(k)ᵀ = [−y(k−1)..−y(k−na), u(k−d)..u(k−d−nb), e(k−1)..e(k−nc)], k ≥ k0.

    Returns (Phi, target y[k0:], k0) with k0 = max(na, nb + delay, nc) so that every
    regressor uses measured samples only.
    """
    N = y.size
    k0 = first_sample(na, nb, nc, delay)
    cols = [-y[k0 - i : N - i] for i in range(1, na + 1)]
    cols += [u[k0 - delay - i : N - delay - i] for i in range(nb + 1)]
    if nc:
        if e is None:
            raise ValueError("nc > 0 needs the c-regressors e")
        cols += [e[k0 - i : N - i] for i in range(1, nc + 1)]
    return np.column_stack(cols), y[k0:], k0


def prediction_errors(theta: np.ndarray, u: np.ndarray, y: np.ndarray, na: int, nb: int,
                      nc: int, delay: int) -> np.ndarray:
    """ε = (A y − q^-d B u) / C for every sample (one-step prediction errors, at rest
    before the record)."""
    a = np.concatenate([[1.0], theta[:na]])
    bd = np.concatenate([np.zeros(delay), theta[na : na + nb + 1]])
    c = np.concatenate([[1.0], theta[na + nb + 1 :]])
    v = lfilter(a, [1.0], y) - lfilter(bd, [1.0], u)
    return lfilter([1.0], c, v)


def stabilise(c: np.ndarray, radius: float = 0.99) -> np.ndarray:
    """Reflect the roots of [1, c...] outside the unit circle into it and shrink those
    beyond ``radius`` onto it (as RELS keeps C); c itself when already inside."""
    if c.size == 0:
        return c
    r = np.roots(np.concatenate([[1.0], c]))
    if r.size == 0 or np.max(np.abs(r)) < radius:
        return c
    out = np.abs(r) > 1
    r[out] = 1 / np.conj(r[out])
    big = np.abs(r) > radius
    r[big] *= radius / np.abs(r[big])
    return np.real(np.poly(r))[1:]


# ---------------------------------------------------------------- the compiled loop's state
def new_state(
    settings: _k.RelsSettings, theta0_scaled: np.ndarray
) -> tuple[np.ndarray, _k.RelsState]:
    """(block, views) of one estimator: θ̂ = θ0, P = P(0), regressors and counters zero."""
    block = _k.new_block(settings)
    return block, start_state(block, settings, theta0_scaled)


def start_state(block: np.ndarray, settings: _k.RelsSettings, theta0_scaled: np.ndarray
                ) -> _k.RelsState:
    """θ̂ = θ0 and P = P(0) = diag(α.., α_c..) in ``block`` (a row of a bank, too); its views."""
    s = settings
    views = _k.state_views(block)
    views.theta[:] = theta0_scaled
    nab = s.na + s.nb + 1
    views.P[:] = np.diag(np.r_[np.full(nab, s.alpha), np.full(s.nc, s.alpha_c)])
    return views


def block_counters(block: np.ndarray) -> dict[str, int]:
    """The counters of the estimator in ``block``, by name."""
    counts = block[_k.N_SETTINGS : _k.NOISE_VAR]
    return {name: int(v) for name, v in zip(_k.COUNTER_NAMES, counts, strict=True)}


def model_from_state(
    views: _k.RelsState, orders: ArmaxOrders, u_scale: float, y_scale: float,
    noise_variance_scaled: float, meta: dict[str, Any],
) -> ArmaxModel:
    """The estimate in ``views`` (scaled units) as a model in physical units.

    Raises
    ------
    IdentificationError
        If a coefficient overflows, or a non-zero one underflows, in physical units.
    """
    o = orders
    dvec = theta_scale(o.na, o.nb, o.nc, u_scale, y_scale)
    theta_s = views.theta
    with np.errstate(over="ignore", under="ignore", invalid="ignore"):  # checked below
        theta = theta_s * dvec
        nv = float(np.float64(noise_variance_scaled) * np.float64(y_scale) ** 2)
        # cov(θ̂) ≈ σ² P for λ = 1 (P ≈ (Σψψᵀ)⁻¹); de-scaled with D: D P D σ²
        cov: np.ndarray | None = noise_variance_scaled * (views.P * dvec[:, None]
                                                          * dvec[None, :])
    if cov is not None and not np.all(np.isfinite(cov)):
        cov = None
    # a coefficient that overflowed, or a non-zero one that underflowed to zero or
    # lost its precision (subnormal), cannot be written in physical units
    tiny = np.finfo(float).tiny
    lost = (np.abs(theta_s) >= tiny) & ~(np.abs(theta) >= tiny)
    if not np.all(np.isfinite(theta)) or np.any(lost):
        raise IdentificationError(
            f"the estimate does not fit float64 in physical units (u scale {u_scale:.3g}, "
            f"y scale {y_scale:.3g}: b = b_scaled·{y_scale:.3g}/{u_scale:.3g}); rescale "
            "u and y to closer magnitudes"
        )
    return ArmaxModel.from_theta(theta, na=o.na, nb=o.nb, nc=o.nc, delay=o.delay, dt=o.dt,
                                 noise_variance=nv, covariance=cov, meta=meta)
