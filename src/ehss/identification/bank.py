"""Many RELS/RML estimators with the same orders in one compiled loop.

:func:`rels_multichannel` identifies one ARMAX model per channel of a record whose
columns are the channels (e.g. the loops of a rig recorded together), and
:class:`RelsBank` is its streaming form: one call per sample carries every channel's
u and y. Each channel is exactly the estimator of :func:`ehss.identification.rels`
and :class:`ehss.identification.RelsEstimator` (the same per-sample step, eqs
(19)–(22) with every safeguard, in the same operation order), so its results are
those of a single-channel run, bit for bit; the bank runs the channels side by side
in one loop, which overlaps their chains of dependent operations and pays the cost of
a call from Python once for all of them (BENCHMARKS.md, "RELS identification").

The loop is compiled for the bank's orders the first time they are used (seconds,
like the single-channel loop; BENCHMARKS.md) and kept in numba's cache on disk.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ehss.errors import DataError, ParameterError
from ehss.identification import _bank_kernels as _b
from ehss.identification import _kernels as _k
from ehss.identification.model import ArmaxModel
from ehss.identification.rels import (
    _check_method,
    _check_p0_c,
    _check_settings,
    _counters,
    _model_from_state,
    _order,
    _real,
    _rms_scale,
    _settings,
    _theta_scale,
    check_record,
)

__all__ = ["rels_multichannel", "RelsBank"]


def _check_channels(u: Any, y: Any) -> tuple[np.ndarray, np.ndarray]:
    """u and y as (N, C) float64 arrays of finite samples, C ≥ 1 channels."""
    u = np.asarray(u, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    if u.ndim != 2 or u.shape != y.shape or u.shape[1] < 1:
        raise DataError(f"u and y must both have shape (n_samples, n_channels); got "
                        f"{u.shape} and {y.shape}")
    for c in range(u.shape[1]):
        check_record(u[:, c], y[:, c])  # finite, as each channel's own record
    return u, y


def _trace_bound(trace_bound: Any, tr0: float) -> float:
    tb = tr0 if trace_bound is None else _real("trace_bound", trace_bound)
    if tb <= 0:
        raise ParameterError(f"trace_bound={trace_bound!r} must be > 0")
    return tb


def _c_radius(c_radius: Any) -> float:
    c_radius = _real("c_radius", c_radius)
    if not 0.0 < c_radius <= 1.0:
        raise ParameterError(f"c_radius={c_radius!r} must be in (0, 1]")
    return c_radius


def rels_multichannel(
    u: Any,
    y: Any,
    *,
    na: int,
    nb: int,
    nc: int,
    delay: int = 1,
    forgetting: float = 1.0,
    p0: float = 1e6,
    p0_c: float | None = None,
    trace_bound: float | None = None,
    c_radius: float = 0.99,
    method: str = "rels",
    dt: float = 1.0,
) -> list[ArmaxModel]:
    """Identify one ARMAX model per channel with RELS (eqs 19–22) or RML, in one loop.

    Parameters
    ----------
    u, y : array_like, shape (n_samples, n_channels)
        Inputs and outputs, one column a channel, finite.
    na, nb, nc, delay, forgetting, p0, p0_c, trace_bound, c_radius, method, dt
        As in :func:`ehss.identification.rels` (one pass), the same for every channel.

    Returns
    -------
    list of ArmaxModel
        One a channel, each equal to ``rels(u[:, c], y[:, c], ...)`` (each channel is
        scaled by its own RMS, as :func:`~ehss.identification.rels` scales it).

    Raises
    ------
    DataError
        Records of another shape, non-finite or too short, or a channel whose u and
        y are too far apart in magnitude for float64.
    ParameterError
        Impossible orders or settings.

    Examples
    --------
    >>> import numpy as np
    >>> from scipy.signal import lfilter
    >>> u = np.random.default_rng(0).standard_normal((2000, 2))
    >>> y = lfilter([0, 0.5], [1, -0.8], u, axis=0)
    >>> [np.round(m.a, 6).tolist() for m in rels_multichannel(u, y, na=1, nb=0, nc=0)]
    [[1.0, -0.8], [1.0, -0.8]]
    """
    na, nb, nc, delay, lam, alpha, dt = _check_settings(na, nb, nc, delay, forgetting, p0, dt)
    alpha_c = _check_p0_c(p0_c, alpha)
    method = _check_method(method)
    tb = _trace_bound(trace_bound, (na + nb + 1) * alpha + nc * alpha_c)
    c_radius = _c_radius(c_radius)
    u, y = _check_channels(u, y)
    n_samples, n_channels = u.shape
    need = max(na, nb + delay, nc) + (na + nb + 1 + nc) + 1
    if n_samples < need:
        raise DataError(f"{n_samples} samples are too few for na={na}, nb={nb}, nc={nc}, "
                        f"delay={delay}: need at least {need}")
    scales = [(_rms_scale(u[:, c]), _rms_scale(y[:, c])) for c in range(n_channels)]
    dvecs = [_theta_scale(na, nb, nc, su, sy) for su, sy in scales]
    for c, dvec in enumerate(dvecs):
        if not np.all((dvec >= np.finfo(float).tiny) & np.isfinite(dvec)):
            raise DataError(f"channel {c}: u and y are too far apart in magnitude for "
                            f"float64 (RMS {scales[c][0]:.3g} and {scales[c][1]:.3g})")
    settings = _settings(na, nb, nc, delay, lam, alpha, alpha_c, tb, c_radius, method)
    blocks = _b.new_blocks(settings, n_channels)
    views = [_start(blocks[c], settings, np.zeros(na + nb + 1 + nc))
             for c in range(n_channels)]
    su_row = np.array([s[0] for s in scales])
    sy_row = np.array([s[1] for s in scales])
    rec = _b.bank_record(u / su_row, y / sy_row)
    _b.bank_kernel(na, nb, nc, delay)(blocks, rec, True)
    models = []
    for c in range(n_channels):
        nv_s = float(np.mean(np.square(rec[3, n_samples // 2 :, c])))
        counts = _counters(blocks[c])
        counts.pop("n_samples")
        meta = {"method": method, "n_samples": int(n_samples), "forgetting": lam,
                "p0": alpha, "p0_c": alpha_c, "passes": 1, "trace_bound": tb,
                "c_radius": c_radius, "u_scale": scales[c][0], "y_scale": scales[c][1],
                "channel": c, **counts}
        model = _model_from_state(views[c], na, nb, nc, delay, dt, scales[c][0],
                                  scales[c][1], nv_s, meta)
        model.check(warn=True)
        models.append(model)
    return models


def _start(block: np.ndarray, settings: _k.RelsSettings, theta_s: np.ndarray
           ) -> _k.RelsState:
    """θ̂ = θ0 and P = P(0) in one channel's block (a row of a bank); its views."""
    s = settings
    views = _k.state_views(block)
    views.theta[:] = theta_s
    nab = s.na + s.nb + 1
    views.P[:] = np.diag(np.r_[np.full(nab, s.alpha), np.full(s.nc, s.alpha_c)])
    return views


class RelsBank:
    """Streaming RELS or RML for many channels with the same orders, in one loop.

    Parameters
    ----------
    n_channels : int
        Number of channels (≥ 1).
    na, nb, nc, delay, forgetting, p0, p0_c, trace_bound, c_radius, method, dt
        As in :class:`ehss.identification.RelsEstimator`, the same for every channel.
    u_scale, y_scale : float or array_like, shape (n_channels,)
        Expected size of each channel's u and y (see :class:`RelsEstimator`); one
        number for all channels or one per channel. Default 1.

    Notes
    -----
    Channel c is the estimator ``RelsEstimator(...)`` with its own ``u_scale[c]``,
    ``y_scale[c]``: :meth:`update` gives each channel's prediction error as that
    estimator's ``update`` would, bit for bit. A call carries every channel's sample,
    so the cost of crossing into the compiled loop is paid once for all channels.

    Examples
    --------
    >>> bank = RelsBank(n_channels=3, na=1, nb=0, nc=0, delay=1)
    >>> bank.update([1.0, 2.0, 3.0], [0.0, 0.0, 0.0]).tolist()
    [0.0, 0.0, 0.0]
    """

    def __init__(
        self,
        *,
        n_channels: int,
        na: int,
        nb: int,
        nc: int,
        delay: int = 1,
        forgetting: float = 1.0,
        p0: float = 1e6,
        p0_c: float | None = None,
        trace_bound: float | None = None,
        c_radius: float = 0.99,
        method: str = "rels",
        u_scale: Any = 1.0,
        y_scale: Any = 1.0,
        dt: float = 1.0,
    ) -> None:
        self._n_channels = _order("n_channels", n_channels, 1)
        na, nb, nc, delay, lam, alpha, dt = _check_settings(
            na, nb, nc, delay, forgetting, p0, dt)
        alpha_c = _check_p0_c(p0_c, alpha)
        self._method = _check_method(method)
        tb = _trace_bound(trace_bound, (na + nb + 1) * alpha + nc * alpha_c)
        self._orders = (na, nb, nc, delay)
        self._dt = dt
        self._us = self._per_channel("u_scale", u_scale)
        self._ys = self._per_channel("y_scale", y_scale)
        self._settings = [
            _settings(na, nb, nc, delay, lam, alpha, alpha_c, tb, _c_radius(c_radius),
                      self._method, u_scale=us, y_scale=ys)
            for us, ys in zip(self._us, self._ys, strict=True)]
        self._run = _b.bank_kernel(na, nb, nc, delay)
        self._sample = np.zeros((4, 1, self._n_channels))
        self.reset()

    def _per_channel(self, name: str, value: Any) -> list[float]:
        values = np.broadcast_to(np.asarray(value, dtype=object), (self._n_channels,))
        out = [_real(name, v) for v in values]
        for v in out:
            if v <= 0:
                raise ParameterError(f"{name}={v!r} must be > 0")
        return out

    def reset(self) -> None:
        """Every channel back to θ̂ = 0, P(0), empty regressor, counters cleared."""
        na, nb, nc, _ = self._orders
        blocks = _b.new_blocks(self._settings[0], self._n_channels)
        self._views = []
        for c, settings in enumerate(self._settings):
            blocks[c, : _k.N_SETTINGS] = [float(v) for v in settings]
            dvec = _theta_scale(na, nb, nc, settings.u_scale, settings.y_scale)
            self._views.append(_start(blocks[c], settings, np.zeros(dvec.size)))
        self._blocks = blocks

    @property
    def n_channels(self) -> int:
        """Number of channels."""
        return self._n_channels

    def update(self, u_k: Any, y_k: Any) -> np.ndarray:
        """Process one sample of every channel; return their a-priori prediction errors.

        Raises
        ------
        DataError
            If ``u_k`` or ``y_k`` is not n_channels finite numbers (the state is then
            left unchanged).
        """
        rec = self._sample
        rec[0, 0] = u_k  # numpy broadcasts a scalar, refuses another length
        rec[1, 0] = y_k
        if not self._run(self._blocks, rec, False):
            raise DataError(f"u_k={u_k!r}, y_k={y_k!r}: samples must be finite (also "
                            "once divided by each channel's u_scale and y_scale)")
        return rec[2, 0].copy()

    def update_many(self, u: Any, y: Any) -> np.ndarray:
        """Process a block of samples, shape (n_samples, n_channels); return the
        a-priori prediction errors, same shape."""
        u, y = _check_channels(u, y)
        if u.shape[1] != self._n_channels:
            raise DataError(f"u has {u.shape[1]} channels, the bank {self._n_channels}")
        rec = _b.bank_record(u, y)
        done = self._run(self._blocks, rec, True)
        if done < u.shape[0]:
            raise DataError(f"sample {done} is not finite once divided by u_scale and "
                            f"y_scale (the {done} samples before it were run)")
        return rec[2].copy()

    def _settle(self) -> None:
        self._run(self._blocks, np.empty((4, 0, self._n_channels)), True)

    @property
    def theta(self) -> np.ndarray:
        """θ̂ of every channel in physical units, shape (n_channels, n_params)."""
        na, nb, nc, _ = self._orders
        return np.array([
            v.theta * _theta_scale(na, nb, nc, us, ys)
            for v, us, ys in zip(self._views, self._us, self._ys, strict=True)])

    @property
    def counters(self) -> list[dict[str, int]]:
        """Each channel's n_samples, resets, c_projections, trace_scalings, skipped."""
        self._settle()
        return [_counters(self._blocks[c]) for c in range(self._n_channels)]

    def model(self, channel: int) -> ArmaxModel:
        """Channel ``channel``'s estimate as an :class:`ArmaxModel` (no stability
        warning), as :attr:`RelsEstimator.model`."""
        c = _order("channel", channel, 0)
        if c >= self._n_channels:
            raise ParameterError(f"channel={channel!r} must be < {self._n_channels}")
        self._settle()
        na, nb, nc, delay = self._orders
        s = self._settings[c]
        meta = {"method": f"{self._method}-bank", "forgetting": s.lam, "p0": s.alpha,
                "p0_c": s.alpha_c, "trace_bound": s.trace_max, "c_radius": s.c_radius,
                "u_scale": s.u_scale, "y_scale": s.y_scale, "channel": c,
                **_counters(self._blocks[c])}
        return _model_from_state(self._views[c], na, nb, nc, delay, self._dt, s.u_scale,
                                 s.y_scale, float(self._blocks[c, _k.NOISE_VAR]), meta)
