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

from typing import Any, Unpack

import numpy as np

from ehss._checks import as_record, check_int, check_real
from ehss.errors import DataError
from ehss.identification import _bank_kernels as _b
from ehss.identification import _kernels as _k
from ehss.identification._common import (
    RelsKeywords,
    RelsSettings,
    block_counters,
    model_from_state,
    record_scales,
    rels_settings,
    start_state,
    theta_scale,
    too_short,
)
from ehss.identification.model import ArmaxModel

__all__ = ["rels_multichannel", "RelsBank"]

def _check_channels(u: Any, y: Any) -> tuple[np.ndarray, np.ndarray]:
    """u and y as (N, C) float64 arrays of finite samples, C ≥ 1 channels."""
    u = np.asarray(u, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    if u.ndim != 2 or u.shape != y.shape or u.shape[1] < 1:
        raise DataError(f"u and y must both have shape (n_samples, n_channels); got "
                        f"{u.shape} and {y.shape}")
    for c in range(u.shape[1]):
        as_record(u[:, c], y[:, c])  # finite, as each channel's own record
    return u, y


def rels_multichannel(
    u: Any, y: Any, *, settings: RelsSettings | None = None, **keywords: Unpack[RelsKeywords],
) -> list[ArmaxModel]:
    """Identify one ARMAX model per channel with RELS (eqs 19–22) or RML, in one loop.

    Parameters
    ----------
    u, y : array_like, shape (n_samples, n_channels)
        Inputs and outputs, one column a channel, finite.
    na, nb, nc, delay, forgetting, p0, p0_c, trace_bound, c_radius, method, dt
        As in :func:`ehss.identification.rels` (one pass), the same for every channel.
    settings : RelsSettings, optional
        All of them in one checked object, instead of the keywords.

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
    TypeError
        Orders or settings of the wrong type.
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
    s = rels_settings(settings, keywords)
    u, y = _check_channels(u, y)
    n_samples, n_channels = u.shape
    too_short(n_samples, s)
    scales = [record_scales(u[:, c], y[:, c], s, f"channel {c}: ")[:2]
              for c in range(n_channels)]
    kernel = s.kernel()
    blocks = _b.new_blocks(kernel, n_channels)
    views = [start_state(blocks[c], kernel, np.zeros(s.n_params)) for c in range(n_channels)]
    su_row = np.array([sc[0] for sc in scales])
    sy_row = np.array([sc[1] for sc in scales])
    rec = _b.bank_record(u / su_row, y / sy_row)
    _b.bank_kernel(s.na, s.nb, s.nc, s.delay)(blocks, rec, True)
    models = []
    for c, (su, sy) in enumerate(scales):
        nv_s = float(np.mean(np.square(rec[3, n_samples // 2 :, c])))
        counts = block_counters(blocks[c])
        counts.pop("n_samples")
        meta = {"method": s.method, "n_samples": int(n_samples), **s.meta(passes=1),
                "u_scale": su, "y_scale": sy, "channel": c, **counts}
        model = model_from_state(views[c], s, su, sy, nv_s, meta)
        model.check(warn=True)
        models.append(model)
    return models


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
    settings : RelsSettings, optional
        The orders and settings in one checked object, instead of the keywords.

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
        u_scale: Any = 1.0,
        y_scale: Any = 1.0,
        settings: RelsSettings | None = None,
        **keywords: Unpack[RelsKeywords],
    ) -> None:
        self._n_channels = check_int(n_channels, "n_channels", lo=1)
        s = self._settings = rels_settings(settings, keywords)
        self._us = self._per_channel("u_scale", u_scale)
        self._ys = self._per_channel("y_scale", y_scale)
        self._channel_settings = [s.kernel(u_scale=us, y_scale=ys)
                          for us, ys in zip(self._us, self._ys, strict=True)]
        self._run = _b.bank_kernel(s.na, s.nb, s.nc, s.delay)
        self._sample = np.zeros((4, 1, self._n_channels))
        self.reset()

    def _per_channel(self, name: str, value: Any) -> list[float]:
        values = np.broadcast_to(np.asarray(value, dtype=object), (self._n_channels,))
        return [check_real(v, name, lo=0.0, lo_open=True) for v in values]

    @property
    def settings(self) -> RelsSettings:
        """The orders and settings every channel shares."""
        return self._settings

    def reset(self) -> None:
        """Every channel back to θ̂ = 0, P(0), empty regressor, counters cleared."""
        blocks = _b.new_blocks(self._channel_settings[0], self._n_channels)
        self._views = []
        for c, settings in enumerate(self._channel_settings):
            blocks[c, : _k.N_SETTINGS] = [float(v) for v in settings]
            self._views.append(start_state(blocks[c], settings, np.zeros(self._settings.n_params)))
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
        s = self._settings
        return np.array([
            v.theta * theta_scale(s.na, s.nb, s.nc, us, ys)
            for v, us, ys in zip(self._views, self._us, self._ys, strict=True)])

    @property
    def counters(self) -> list[dict[str, int]]:
        """Each channel's n_samples, resets, c_projections, trace_scalings, skipped."""
        self._settle()
        return [block_counters(self._blocks[c]) for c in range(self._n_channels)]

    def model(self, channel: int) -> ArmaxModel:
        """Channel ``channel``'s estimate as an :class:`ArmaxModel` (no stability
        warning), as :attr:`RelsEstimator.model`."""
        c = check_int(channel, "channel", lo=0, hi=self._n_channels - 1)
        self._settle()
        s = self._settings
        us, ys = self._us[c], self._ys[c]
        meta = {"method": f"{s.method}-bank", **s.meta(), "u_scale": us,
                "y_scale": ys, "channel": c, **block_counters(self._blocks[c])}
        return model_from_state(self._views[c], s, us, ys,
                                float(self._blocks[c, _k.NOISE_VAR]), meta)
