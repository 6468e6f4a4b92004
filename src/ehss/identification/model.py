"""The identified discrete ARMAX model and its conversions (paper eqs 16–18, 23–25).

.. math::

    A(q^{-1}) y(k) = q^{-d} B(q^{-1}) u(k) + C(q^{-1}) \\xi(k)

with ``a = [1, a1..a_na]``, ``b = [b0..b_nb]`` (b_i multiplies u(k−d−i)) and
``c = [1, c1..c_nc]``. The deterministic part G(z) = z^{−d} B(z^{−1}) / A(z^{−1}).

The paper prints its identified models (eqs 23–25) with 4 significant digits, and
that rounding destroys them (PAPER.md §5). Models here are therefore stored and
printed at full float64 precision by default, and :meth:`ArmaxModel.rounding_sensitivity`
quantifies what rounding would do.
"""

from __future__ import annotations

import json
import math
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ehss._checks import (
    SAMPLE_RATE_RANGE_HZ,
    check_int,
    check_real,
    is_integer,
    is_real,
    show,
)
from ehss._files import atomic_path, parse_document, read_small_file
from ehss.errors import DataError, EhssWarning, ParameterError

__all__ = ["ArmaxModel", "RoundingSensitivity"]


def real_array(value: Any, name: str) -> np.ndarray:
    """``value`` as a new float64 array (TypeError unless it holds real numbers:
    strings, None, complex or a ragged nesting are refused)."""
    try:
        arr = np.asarray(value)
        if arr.dtype.kind not in "iuf":
            raise TypeError(f"dtype {arr.dtype}")
    except (TypeError, ValueError):  # a ragged list cannot even be an array
        raise TypeError(f"{name}={show(value)} must be a sequence of real numbers, not "
                        f"{type(value).__name__}") from None
    return np.array(arr, dtype=np.float64, copy=True)


def _coeffs(name: str, value: Any, *, monic: bool) -> np.ndarray:
    """``value`` as a read-only float64 vector of finite coefficients.

    Raises
    ------
    TypeError
        If ``value`` does not hold real numbers (see :func:`real_array`).
    ParameterError
        If it is empty, not finite or (``monic``) does not start with 1.
    """
    arr = real_array(value, name).reshape(-1)
    if arr.size == 0:
        raise ParameterError(f"{name}={value!r} must have at least one coefficient")
    if not np.all(np.isfinite(arr)):
        raise ParameterError(f"{name}={value!r} must be finite")
    if monic and arr[0] != 1.0:
        raise ParameterError(f"{name}={value!r} must start with 1 (monic polynomial)")
    arr.setflags(write=False)
    return arr


def _pair(name: str, value: Any) -> tuple[float, float]:
    """``value`` as a pair of finite floats (TypeError if it is not a pair of real
    numbers, ParameterError if one is not finite)."""
    try:
        lo, hi = value
    except (TypeError, ValueError):
        raise TypeError(f"{name}={show(value)} must be a pair of numbers, not "
                        f"{type(value).__name__}") from None
    return check_real(lo, f"{name}[0]"), check_real(hi, f"{name}[1]")


def _jsonable(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _jsonable(obj.tolist())
    if isinstance(obj, np.generic):
        return _jsonable(obj.item())
    if isinstance(obj, float) and not math.isfinite(obj):
        return None if math.isnan(obj) else ("inf" if obj > 0 else "-inf")
    return obj


@dataclass(frozen=True, kw_only=True)
class RoundingSensitivity:
    """How far the poles move when the coefficients are rounded.

    Attributes
    ----------
    digits : int
        Significant digits kept.
    max_pole_shift : float
        Largest |p_rounded − p| over matched pole pairs.
    max_relative_shift : float
        Largest |p_rounded − p| / max(|p|, 1e-12).
    max_radius : float
        Max pole radius of the exact model.
    max_radius_rounded : float
        Max pole radius after rounding.
    stability_changed : bool
        True if rounding changes ``max_radius < 1``.
    """

    digits: int
    max_pole_shift: float
    max_relative_shift: float
    max_radius: float
    max_radius_rounded: float
    stability_changed: bool

    @property
    def material(self) -> bool:
        """Relative pole shift above 1 % or a change of stability."""
        return self.stability_changed or self.max_relative_shift > 0.01


@dataclass(frozen=True, kw_only=True, eq=False)
class ArmaxModel:
    """A discrete ARMAX model ``A y = q^-d B u + C ξ`` sampled every ``dt`` seconds.

    Parameters
    ----------
    a : array_like, shape (na+1,)
        ``[1, a1..a_na]``.
    b : array_like, shape (nb+1,)
        ``[b0..b_nb]``; b_i multiplies u(k−delay−i).
    c : array_like, shape (nc+1,)
        ``[1, c1..c_nc]``.
    delay : int
        Input delay d ≥ 0 in samples.
    dt : float
        Sample period in seconds.
    noise_variance : float
        Variance of the white innovation ξ (NaN when unknown).
    covariance : ndarray or None
        Covariance of θ = [a1..a_na, b0..b_nb, c1..c_nc].
    meta : dict
        Free-form extra information (n_samples, forgetting, resets, ...).
    offsets : tuple of float or None
        Operating point ``(u0, y0)`` the model was identified about: the model relates
        ``u - u0`` to ``y - y0``. None when the record was used as it is.
    band_hz : tuple of float or None
        ``(f_lo, f_hi)``, the band over which the model was validated (e.g. where the
        validation record's coherence was high). Compensation limits its inverse to this
        band by default. None when unknown.

    Examples
    --------
    >>> m = ArmaxModel(a=[1, -0.5], b=[0.5], c=[1], delay=1, dt=1e-3)
    >>> float(m.dc_gain())
    1.0
    """

    a: np.ndarray
    b: np.ndarray
    c: np.ndarray = field(default_factory=lambda: np.ones(1))
    delay: int = 1
    dt: float = 1.0
    noise_variance: float = math.nan
    covariance: np.ndarray | None = None
    meta: dict = field(default_factory=dict)
    offsets: tuple[float, float] | None = None
    band_hz: tuple[float, float] | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "a", _coeffs("a", self.a, monic=True))
        object.__setattr__(self, "b", _coeffs("b", self.b, monic=False))
        object.__setattr__(self, "c", _coeffs("c", self.c, monic=True))
        object.__setattr__(self, "delay", check_int(self.delay, "delay", lo=0))
        object.__setattr__(self, "dt", check_real(self.dt, "dt", lo=0.0, lo_open=True,
                                                  unit="s"))
        if not is_real(self.noise_variance):
            raise TypeError(f"noise_variance={show(self.noise_variance)} must be a real "
                            f"number, not {type(self.noise_variance).__name__}")
        object.__setattr__(self, "noise_variance", float(self.noise_variance))
        if self.covariance is not None:
            cov = np.array(self.covariance, dtype=np.float64, copy=True)
            n = self.na + self.nb + 1 + self.nc
            if cov.shape != (n, n):
                raise ParameterError(
                    f"covariance shape {cov.shape} must be ({n}, {n}) for these orders"
                )
            cov.setflags(write=False)
            object.__setattr__(self, "covariance", cov)
        object.__setattr__(self, "meta", dict(self.meta))
        if self.offsets is not None:
            object.__setattr__(self, "offsets", _pair("offsets", self.offsets))
        if self.band_hz is not None:
            lo, hi = _pair("band_hz", self.band_hz)
            if not 0.0 <= lo < hi <= 0.5 / self.dt * (1 + 1e-12):
                raise ParameterError(
                    f"band_hz={self.band_hz!r} must satisfy 0 <= lo < hi <= fs/2 = "
                    f"{0.5 / self.dt:g} Hz"
                )
            object.__setattr__(self, "band_hz", (lo, hi))

    # ------------------------------------------------------------------ orders
    @property
    def na(self) -> int:
        """Order of A."""
        return self.a.size - 1

    @property
    def nb(self) -> int:
        """Order of B (len(b) − 1)."""
        return self.b.size - 1

    @property
    def nc(self) -> int:
        """Order of C."""
        return self.c.size - 1

    @property
    def fs(self) -> float:
        """Sample rate in Hz."""
        return 1.0 / self.dt

    @property
    def theta(self) -> np.ndarray:
        """θ = [a1..a_na, b0..b_nb, c1..c_nc] (eq 18)."""
        return np.concatenate([self.a[1:], self.b, self.c[1:]])

    @classmethod
    def from_theta(
        cls, theta: Any, *, na: int, nb: int, nc: int, delay: int, dt: float,
        noise_variance: float = math.nan, covariance: Any = None, meta: dict | None = None,
    ) -> ArmaxModel:
        """The model of θ = [a1..a_na, b0..b_nb, c1..c_nc] (eq 18), the inverse of
        :attr:`theta`.

        A non-finite ``noise_variance`` is stored as NaN (unknown) and a ``covariance``
        with a non-finite entry as None, so that an estimator's result is always a valid
        model; θ itself must be finite (ParameterError otherwise).

        Examples
        --------
        >>> m = ArmaxModel.from_theta([-0.5, 0.5, 0.2], na=1, nb=0, nc=1, delay=1, dt=1e-3)
        >>> m.a.tolist(), m.b.tolist(), m.c.tolist()
        ([1.0, -0.5], [0.5], [1.0, 0.2])
        """
        theta = np.asarray(theta, dtype=np.float64).reshape(-1)
        n = na + nb + 1 + nc
        if theta.size != n:
            raise ParameterError(f"theta has {theta.size} coefficients, must have "
                                 f"na + nb + 1 + nc = {n}")
        nv = float(noise_variance)
        if covariance is not None and not np.all(np.isfinite(covariance)):
            covariance = None
        return cls(
            a=np.concatenate([[1.0], theta[:na]]), b=theta[na : na + nb + 1],
            c=np.concatenate([[1.0], theta[na + nb + 1 :]]), delay=delay, dt=dt,
            noise_variance=nv if math.isfinite(nv) else math.nan, covariance=covariance,
            meta={} if meta is None else meta,
        )

    # ------------------------------------------------------------------ forms
    def paper_form(self) -> tuple[np.ndarray, np.ndarray]:
        """(num, den) in descending powers of z with G(z) = num(z)/den(z), equal lengths.

        G(z) = z^{−d} B(z^{−1}) / A(z^{−1}); both multiplied by z^n, n = max(na, nb + d).
        """
        n = max(self.na, self.nb + self.delay)
        num = np.zeros(n + 1)
        num[self.delay : self.delay + self.nb + 1] = self.b
        den = np.zeros(n + 1)
        den[: self.na + 1] = self.a
        return num, den

    @classmethod
    def from_paper_form(
        cls, num: Any, den: Any, *, dt: float, c: Any = (1.0,), **kwargs: Any
    ) -> ArmaxModel:
        """Inverse of :meth:`paper_form` (den must be monic in its leading coefficient)."""
        num = np.asarray(num, dtype=np.float64).reshape(-1)
        den = np.asarray(den, dtype=np.float64).reshape(-1)
        if den.size == 0 or den[0] == 0:
            raise ParameterError(f"den={den!r} must have a non-zero leading coefficient")
        if num.size > den.size:
            raise ParameterError("num must not be longer than den (the model must be causal)")
        num = np.concatenate([np.zeros(den.size - num.size), num]) / den[0]
        den = den / den[0]
        nz = np.flatnonzero(num)
        if nz.size == 0:
            delay, b = 0, np.zeros(1)
        else:
            delay = int(nz[0])
            b = np.trim_zeros(num[delay:], "b")
        a = np.trim_zeros(den, "b")
        return cls(a=a, b=b, c=c, delay=delay, dt=dt, **kwargs)

    def poles(self) -> np.ndarray:
        """Poles of G(z) (roots of den in :meth:`paper_form`)."""
        return np.roots(self.paper_form()[1])

    def zeros(self) -> np.ndarray:
        """Finite zeros of G(z)."""
        num = self.paper_form()[0]
        if not np.any(num):
            return np.zeros(0, dtype=complex)
        return np.roots(num)

    def dc_gain(self) -> float:
        """G(1) = ΣB / ΣA (±inf for a pole at z = 1)."""
        sa, sb = float(np.sum(self.a)), float(np.sum(self.b))
        if sa == 0.0:
            return math.copysign(math.inf, sb) if sb != 0 else math.nan
        return sb / sa

    def max_pole_radius(self) -> float:
        """Largest |pole| (0 for a FIR model)."""
        p = self.poles()
        return float(np.max(np.abs(p))) if p.size else 0.0

    def is_stable(self) -> bool:
        """True if all poles lie strictly inside the unit circle."""
        return self.max_pole_radius() < 1.0

    def check(self, *, warn: bool = True) -> bool:
        """Return :meth:`is_stable`; warn with EhssWarning if the model is unstable."""
        ok = self.is_stable()
        if not ok and warn:
            warnings.warn(
                f"identified model is unstable: max pole radius {self.max_pole_radius():.6g} "
                ">= 1; do not use it as a plant or invert it without care",
                EhssWarning,
                stacklevel=2,
            )
        return ok

    # ------------------------------------------------------------------ responses
    def frequency_response(self, freq_hz: Any) -> np.ndarray:
        """G(e^{jω dt}) = e^{−jω dt d} B/A at the given frequencies (Hz)."""
        f = np.asarray(freq_hz, dtype=np.float64)
        zi = np.exp(-2j * np.pi * f * self.dt)  # z^-1
        num = np.polyval(self.b[::-1], zi)
        den = np.polyval(self.a[::-1], zi)
        return zi**self.delay * num / den

    def simulate(self, u: Any, innovation: Any = None) -> np.ndarray:
        """Output of the model with zero initial conditions: y = q^-d B/A u (+ C/A ξ).

        Parameters
        ----------
        u : array_like, shape (n_samples,)
            Input.
        innovation : array_like, shape (n_samples,), optional
            The white noise ξ of the model; without it the output is noise-free.

        Raises
        ------
        DataError
            If ``innovation`` and ``u`` differ in shape.
        """
        from scipy.signal import lfilter

        u = np.asarray(u, dtype=np.float64)
        bd = np.concatenate([np.zeros(self.delay), self.b])
        y = lfilter(bd, self.a, u)
        if innovation is None:
            return y
        e = np.asarray(innovation, dtype=np.float64)
        if e.shape != u.shape:
            raise DataError(f"innovation has shape {e.shape}, the input {u.shape}: they "
                            "must match")
        return y + lfilter(self.c, self.a, e)

    def predict(self, u: Any, y: Any, horizon: int = 1) -> np.ndarray:
        """k-step-ahead ARMAX predictor ŷ(k | k − horizon), zero initial conditions.

        With C = A F + q^{−h} G (F of degree h−1, the first h terms of C/A):
        ŷ(k|k−h) = (q^{−h} G / C) y(k) + (F q^{−d} B / C) u(k). For h = 1 this is
        ŷ = (1 − A/C) y + (q^{−d} B / C) u.
        """
        from scipy.signal import lfilter

        horizon = check_int(horizon, "horizon", lo=1)
        u = np.asarray(u, dtype=np.float64)
        y = np.asarray(y, dtype=np.float64)
        if u.shape != y.shape or u.ndim != 1:
            raise DataError(f"u and y must be 1-D of equal length, got {u.shape} and {y.shape}")
        h = int(horizon)
        # long division C/A to h terms: F; remainder q^-h G = C − A F
        m = max(self.na, self.nc) + h
        cpad = np.zeros(m + 1)
        cpad[: self.nc + 1] = self.c
        apad = np.zeros(m + 1)
        apad[: self.na + 1] = self.a
        f = np.zeros(h)
        rem = cpad.copy()
        for i in range(h):
            f[i] = rem[i]
            rem[i:] -= f[i] * apad[: m + 1 - i]
        gpoly = rem  # = C − A F, zeros in the first h entries
        ypart = lfilter(gpoly, self.c, y)
        bd = np.concatenate([np.zeros(self.delay), self.b])
        upart = lfilter(np.convolve(f, bd), self.c, u)
        return ypart + upart

    # ------------------------------------------------------------------ conversions
    def to_control(self) -> Any:
        """python-control TransferFunction with ``dt``."""
        import control

        num, den = self.paper_form()
        return control.tf(num, den, self.dt)

    def to_scipy(self) -> Any:
        """scipy.signal.dlti (transfer-function form, descending powers of z)."""
        from scipy import signal

        num, den = self._trimmed()
        return signal.dlti(num, den, dt=self.dt)

    def to_sos(self) -> np.ndarray:
        """Second-order sections (scipy.signal.tf2sos), shape (n_sections, 6).

        B/A goes through ``tf2sos``; the delay z^{−d} is appended as pure-delay sections
        ([0, 0, 1, 1, 0, 0] = z^{−2}, [0, 1, 0, 1, 0, 0] = z^{−1}), because leading zeros
        in the numerator make scipy warn and drop the delay.
        """
        from scipy import signal

        n = max(self.na, self.nb)
        bb = np.zeros(n + 1)
        bb[: self.nb + 1] = self.b
        aa = np.zeros(n + 1)
        aa[: self.na + 1] = self.a
        sos = signal.tf2sos(bb, aa)
        extra = [[0.0, 0.0, 1.0, 1.0, 0.0, 0.0]] * (self.delay // 2)
        if self.delay % 2:
            extra.append([0.0, 1.0, 0.0, 1.0, 0.0, 0.0])
        return np.vstack([sos, *extra]) if extra else sos

    def _trimmed(self) -> tuple[np.ndarray, np.ndarray]:
        # scipy warns (BadCoefficients) on exact leading zeros in num (the delay): strip
        # them; G(z) is unchanged because den keeps its full degree.
        num, den = self.paper_form()
        nz = np.flatnonzero(num)
        num = num[nz[0] :] if nz.size else np.zeros(1)
        return num, den

    def format_paper(self, precision: int | None = None) -> str:
        """G(z) as the paper prints it, at full precision (repr) unless ``precision``."""

        def fmt(x: float) -> str:
            return repr(float(x)) if precision is None else f"{x:.{precision}g}"

        num, den = self.paper_form()
        n = num.size - 1

        def poly(p: np.ndarray) -> str:
            terms = []
            for i, v in enumerate(p):
                if v == 0:
                    continue
                pw = n - i
                zs = "" if pw == 0 else (" z" if pw == 1 else f" z^{pw}")
                terms.append(f"{fmt(v)}{zs}")
            return " + ".join(terms).replace("+ -", "- ") or "0"

        return f"G(z) = ({poly(num)}) / ({poly(den)})"

    def rounding_sensitivity(self, digits: int = 4, *, warn: bool = True) -> RoundingSensitivity:
        """Pole movement when a and b are rounded to ``digits`` significant digits.

        Warns (EhssWarning) when the relative pole shift exceeds 1 % or stability changes.
        """
        from scipy.optimize import linear_sum_assignment

        digits = check_int(digits, "digits", lo=1)

        def rnd(v: np.ndarray) -> np.ndarray:
            return np.array([float(f"{x:.{digits}g}") for x in v])

        rounded = ArmaxModel(
            a=np.concatenate([[1.0], rnd(self.a[1:])]), b=rnd(self.b), c=self.c,
            delay=self.delay, dt=self.dt,
        )
        p0, p1 = self.poles(), rounded.poles()
        if p0.size:
            cost = np.abs(p0[:, None] - p1[None, :])
            r, c = linear_sum_assignment(cost)
            shift = cost[r, c]
            rel = shift / np.maximum(np.abs(p0[r]), 1e-12)
            max_shift, max_rel = float(shift.max()), float(rel.max())
        else:
            max_shift = max_rel = 0.0
        r0, r1 = self.max_pole_radius(), rounded.max_pole_radius()
        res = RoundingSensitivity(
            digits=int(digits), max_pole_shift=max_shift, max_relative_shift=max_rel,
            max_radius=r0, max_radius_rounded=r1, stability_changed=(r0 < 1.0) != (r1 < 1.0),
        )
        if warn and res.material:
            warnings.warn(
                f"rounding the model to {digits} significant digits moves its poles by up "
                f"to {100 * max_rel:.3g} % (max radius {r0:.6g} -> {r1:.6g}); store and "
                "print it at full precision or as second-order sections",
                EhssWarning,
                stacklevel=2,
            )
        return res

    # ------------------------------------------------------------------ JSON
    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict at full float64 precision (floats round-trip through repr)."""
        nv = self.noise_variance
        return {
            "a": self.a.tolist(),
            "b": self.b.tolist(),
            "c": self.c.tolist(),
            "delay": self.delay,
            "dt": self.dt,
            "noise_variance": None if math.isnan(nv) else nv,
            "covariance": None if self.covariance is None else self.covariance.tolist(),
            "meta": _jsonable(self.meta),
            "offsets": (None if self.offsets is None
                        else {"input": self.offsets[0], "output": self.offsets[1]}),
            "band_hz": None if self.band_hz is None else list(self.band_hz),
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> ArmaxModel:
        """Inverse of :meth:`to_dict`, checking every field's type and shape.

        Keys other than those of :meth:`to_dict` (such as ``validation``) are ignored.

        Raises
        ------
        DataError
            If a field is missing, of the wrong type or shape (strings for numbers,
            nested or ragged lists, a fractional delay...) or out of range. The message
            names the field.
        """
        return cls(**_fields_from_dict(d))

    def save_json(self, path: str | Path) -> None:
        """Write :meth:`to_dict` as JSON (atomically)."""
        with atomic_path(path) as tmp:
            tmp.write_text(json.dumps(self.to_dict(), indent=2) + "\n")

    @classmethod
    def load_json(cls, path: str | Path) -> ArmaxModel:
        """Read a model written by :meth:`save_json`.

        Raises
        ------
        DataError
            If the file is missing, unreadable, a folder, empty, not UTF-8, not JSON, too
            deeply nested or too large, or if a field is malformed (see :meth:`from_dict`);
            the message names the file and the field.
        """
        path = Path(path)
        where = f"model file {str(path)!r}"
        raw = read_small_file(path, where, max_bytes=MAX_MODEL_FILE_BYTES)
        if not raw.strip():
            raise DataError(f"{where} is empty")
        d = parse_document(raw, where, parse=json.loads, syntax_error=json.JSONDecodeError,
                           syntax="JSON", kind="a model", encoding="utf-8-sig")
        if not isinstance(d, dict):
            raise DataError(f"{where} does not hold a JSON object (it holds a "
                            f"{type(d).__name__})")
        try:
            return cls.from_dict(d)
        except DataError as exc:
            raise DataError(f"{where}: {exc}") from None


#: Largest model file read (bytes); a model with its covariance is a few kB.
MAX_MODEL_FILE_BYTES = 64 << 20
#: Most coefficients in one polynomial of a model read from a file.
MAX_COEFFICIENTS = 1001
#: Largest input delay (samples) of a model read from a file.
MAX_DELAY = 100_000


def _number(value: Any, field_name: str) -> float:
    """A finite float from a JSON number (bools and strings refused)."""
    if not is_real(value):
        raise DataError(f"field {field_name!r} = {show(value)} must be a number, not "
                        f"{_json_type(value)}")
    try:
        x = float(value)
    except OverflowError:
        raise DataError(f"field {field_name!r} = {show(value)} is too large") from None
    if not math.isfinite(x):
        raise DataError(f"field {field_name!r} = {show(value)} must be finite")
    return x


def _json_type(value: Any) -> str:
    names = {str: "a string", list: "a list", dict: "an object", bool: "true/false",
             type(None): "null"}
    return names.get(type(value), type(value).__name__)


def _number_list(value: Any, field_name: str, *, max_len: int = MAX_COEFFICIENTS
                 ) -> np.ndarray:
    """A flat, non-empty list of finite numbers as a float64 array."""
    if isinstance(value, np.ndarray):
        value = value.tolist()
    if isinstance(value, tuple):
        value = list(value)
    if not isinstance(value, list):
        raise DataError(f"field {field_name!r} = {show(value)} must be a list of numbers, "
                        f"not {_json_type(value)}")
    if not value:
        raise DataError(f"field {field_name!r} is empty; it needs at least one coefficient")
    if len(value) > max_len:
        raise DataError(f"field {field_name!r} has {len(value)} entries; at most {max_len} "
                        "are accepted")
    out = np.empty(len(value))
    for i, x in enumerate(value):
        if isinstance(x, (list, tuple, dict)):
            raise DataError(f"field {field_name!r} must be a flat list of numbers, but entry "
                            f"{i} is {_json_type(x)} (a 2-D or ragged array)")
        out[i] = _number(x, f"{field_name}[{i}]")
    return out


def _polynomial(d: dict, key: str, *, monic: bool) -> np.ndarray:
    arr = _number_list(d[key], key)
    if monic and arr[0] != 1.0:
        raise DataError(f"field {key!r} must start with 1 (a monic polynomial), "
                        f"got {arr[0]!r}")
    return arr


def _fields_from_dict(d: Any) -> dict[str, Any]:
    """Checked constructor arguments of :class:`ArmaxModel` from a JSON-like dict."""
    if not isinstance(d, dict):
        raise DataError(f"a model must be a JSON object, not {_json_type(d)}")
    missing = [k for k in ("a", "b", "delay", "dt") if k not in d]
    if missing:
        raise DataError(f"model lacks the field{'s' if len(missing) > 1 else ''} "
                        f"{', '.join(missing)}")
    a = _polynomial(d, "a", monic=True)
    b = _polynomial(d, "b", monic=False)
    if not np.any(b):
        raise DataError("field 'b' is all zeros: the model has no path from input to output")
    c = _polynomial(d, "c", monic=True) if d.get("c") is not None else np.ones(1)
    delay = _field_delay(d["delay"])
    dt = _field_dt(d["dt"])
    return dict(a=a, b=b, c=c, delay=delay, dt=dt,
                noise_variance=_field_noise_variance(d.get("noise_variance")),
                covariance=_field_covariance(d.get("covariance"),
                                             a.size + b.size + c.size - 2),
                meta=_field_meta(d.get("meta"), a, b), offsets=_field_offsets(d.get("offsets")),
                band_hz=_field_band(d.get("band_hz"), dt))


def _field_delay(delay: Any) -> int:
    """The field 'delay': a whole number of samples in [0, MAX_DELAY]."""
    if isinstance(delay, float) and delay.is_integer():
        delay = int(delay)  # some JSON writers give every number a decimal point
    if not is_integer(delay):
        raise DataError(f"field 'delay' = {show(delay)} must be a whole number of samples in "
                        f"[0, {MAX_DELAY}]")
    if not 0 <= delay <= MAX_DELAY:
        raise DataError(f"field 'delay' = {delay} must be in [0, {MAX_DELAY}] samples")
    return int(delay)


def _field_dt(value: Any) -> float:
    """The field 'dt': a sample period whose rate is in ``SAMPLE_RATE_RANGE_HZ``."""
    dt = _number(value, "dt")
    lo_fs, hi_fs = SAMPLE_RATE_RANGE_HZ
    if not 1.0 / hi_fs <= dt <= 1.0 / lo_fs:
        raise DataError(f"field 'dt' = {dt!r} s must be a sample period in "
                        f"[{1.0 / hi_fs:g}, {1.0 / lo_fs:g}] s")
    return dt


def _field_noise_variance(value: Any) -> float:
    """The field 'noise_variance' (≥ 0), NaN when it is absent."""
    if value is None:
        return math.nan
    nv = _number(value, "noise_variance")
    if nv < 0:
        raise DataError(f"field 'noise_variance' = {nv!r} must be >= 0")
    return nv


def _field_covariance(cov: Any, n: int) -> np.ndarray | None:
    """The field 'covariance': n rows of n numbers, or None."""
    if cov is None:
        return None
    if not isinstance(cov, list) or len(cov) != n or not all(
            isinstance(row, list) and len(row) == n for row in cov):
        raise DataError(f"field 'covariance' must be a list of {n} rows of {n} numbers "
                        "for these orders (a square matrix)")
    return np.array([_number_list(row, f"covariance[{i}]", max_len=n)
                     for i, row in enumerate(cov)])


def _field_meta(meta: Any, a: np.ndarray, b: np.ndarray) -> dict[str, Any]:
    """The field 'meta': an object (empty when absent), its known factors checked."""
    if meta is None:
        return {}
    if not isinstance(meta, dict):
        raise DataError(f"field 'meta' must be an object, not {_json_type(meta)}")
    if meta.get("known_factors") is not None:
        _check_known_factors(meta["known_factors"], a, b)
    return meta


def _field_offsets(off: Any) -> tuple[float, float] | None:
    """The field 'offsets': {"input": number, "output": number}, or None."""
    if off is None:
        return None
    if not isinstance(off, dict) or set(off) != {"input", "output"}:
        raise DataError("field 'offsets' must be an object with the numbers 'input' and "
                        f"'output', got {show(off)}")
    return _number(off["input"], "offsets.input"), _number(off["output"], "offsets.output")


def _field_band(band: Any, dt: float) -> tuple[float, float] | None:
    """The field 'band_hz': [lo, hi] in Hz with 0 <= lo < hi <= fs/2, or None."""
    if band is None:
        return None
    if not isinstance(band, list) or len(band) != 2:
        raise DataError(f"field 'band_hz' = {show(band)} must be a list [lo, hi] in Hz")
    lo, hi = (_number(x, f"band_hz[{i}]") for i, x in enumerate(band))
    if not 0.0 <= lo < hi <= 0.5 / dt * (1 + 1e-12):
        raise DataError(f"field 'band_hz' = {show(band)} must satisfy 0 <= lo < hi <= "
                        f"fs/2 = {0.5 / dt:g} Hz")
    return lo, hi


def _check_known_factors(known: Any, a: np.ndarray, b: np.ndarray) -> None:
    """``meta.known_factors`` = {"num": [...], "den": [...]} dividing ``b`` and ``a``.

    A model identified behind known factors F = N/D (see
    :func:`ehss.identification.known.compose`) has ``b = N * B_rest`` and ``a = D * A_rest``
    (polynomial products); compensation divides them back out.
    """
    name = "meta.known_factors"
    if not isinstance(known, dict) or set(known) != {"num", "den"}:
        raise DataError(f"field {name!r} must be an object with the coefficient lists 'num' "
                        f"and 'den', got {show(known)}")
    num = _number_list(known["num"], f"{name}.num")
    den = _number_list(known["den"], f"{name}.den")
    if num[0] == 0.0 or den[0] == 0.0:
        raise DataError(f"field {name!r}: num[0] and den[0] must not be 0")
    if den.size > 1 and np.max(np.abs(np.roots(den))) >= 1.0:
        raise DataError(f"field {name!r}: den has a pole on or outside the unit circle "
                        "(an unstable known factor cannot be divided out)")
    for poly, factor, what, key in ((b, num, "num", "b"), (a, den, "den", "a")):
        if factor.size > poly.size:
            raise DataError(f"field {name!r}: {what} is longer than the model's {key!r}, so "
                            f"it cannot be a factor of it")
        _, rem = np.polydiv(poly, factor)
        if np.max(np.abs(rem)) > 1e-8 * np.max(np.abs(poly)):
            raise DataError(f"field {name!r}: {what} does not divide the model's {key!r} "
                            "(the known factors do not belong to this model)")
