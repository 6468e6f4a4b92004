"""Recursive ARMAX identification: RELS (paper eqs 19–22) and RML.

.. math::

    \\hat\\theta(k) &= \\hat\\theta(k-1) + K(k)\\,[y(k) - \\hat\\psi^T(k)\\hat\\theta(k-1)]
        \\qquad (20)\\\\
    K(k) &= P(k-1)\\hat\\psi(k) / (\\lambda + \\hat\\psi^T(k) P(k-1) \\hat\\psi(k))
        \\qquad (21)\\\\
    P(k) &= [I - K(k)\\hat\\psi^T(k)] P(k-1) / \\lambda \\qquad (22)\\\\
    \\hat\\xi(k) &= y(k) - \\hat\\psi^T(k)\\hat\\theta(k) \\qquad (19)

with θ = [a1..a_na, b0..b_nb, c1..c_nc] and
ψ̂(k) = [−y(k−1)..−y(k−na), u(k−d)..u(k−d−nb), ξ̂(k−1)..ξ̂(k−nc)].

Departures from the textbook, all for numerical soundness (PAPER.md §3):

* P is updated in the symmetric rank-1 form (P − g gᵀ/den)/λ with g = Pψ̂ shared,
  computed as P/λ − w wᵀ with w = g √(1/(den λ)), which keeps P bit-exactly symmetric
  (the textbook form drifts and diverges at λ < 1);
* tr P is bounded (default tr P(0)) against wind-up under poor excitation;
* if P loses positive definiteness or anything becomes non-finite, P is reset to P(0)
  (θ̂ is kept) and the reset is counted;
* C(q⁻¹) is kept inside ``c_radius`` (roots reflected / shrunk, as MATLAB does),
  checked every sample by a Rouché bound then an exact O(nc²) Schur–Cohn test;
* the batch function scales u and y by their RMS so that α = 1e6 means the same thing
  for any units; the result is de-scaled (b by s_y/s_u, noise variance by s_y²).

``method="rml"`` selects recursive maximum likelihood instead, the recursive
prediction-error method for ARMAX (Ljung & Söderström, *Theory and Practice of
Recursive Identification*, MIT Press 1983, RML/RPEM for ARMAX): the prediction error,
θ̂ and ξ̂ are as above, but the gain (21) and the P update (22) use the regressor
filtered through 1/Ĉ(q⁻¹),

.. math::

    \\psi_f(k) = \\hat\\psi(k) - \\hat c_1 \\psi_f(k-1) - \\dots
        - \\hat c_{n_c} \\psi_f(k-n_c),

the gradient of the prediction error. RELS converges only where 1/C − 1/2 is strictly
positive real, which fails when C has roots near the unit circle — e.g. output-error
records (white sensor noise at the output: the ARMAX noise model needs C ≈ A, lightly
damped). RML with nc = na does not need that condition. All the safeguards above apply
to RML as well (a reset of P also restarts the filter 1/Ĉ from rest).
"""

from __future__ import annotations

import dataclasses
from typing import Any, Unpack

import numpy as np

from ehss._checks import as_record, check_int, check_real, is_real
from ehss.errors import DataError
from ehss.identification import _kernels as _k
from ehss.identification._common import (
    ArmaxOrders,
    RelsKeywords,
    RelsSettings,
    block_counters,
    check_theta0,
    model_from_state,
    new_state,
    record_scales,
    rels_settings,
    theta_scale,
    too_short,
)
from ehss.identification.model import ArmaxModel

__all__ = ["rels", "RelsEstimator", "specialise_rels"]

#: index of the bound of tr P among the settings at the start of an estimator's block
_TRACE_MAX = _k.RelsSettings._fields.index("trace_max")
#: index of λ among them
_LAM = _k.RelsSettings._fields.index("lam")

# ---------------------------------------------------------------- validation helpers
def _sample(name: str, value: Any) -> float:
    """One streaming sample as a Python float (TypeError for anything but a real number)."""
    if not is_real(value):
        hint = " (use update_many for arrays)" if isinstance(value, (np.ndarray, list,
                                                                     tuple)) else ""
        raise TypeError(
            f"{name}={value!r} must be a real number (int or float), not "
            f"{type(value).__name__}{hint}"
        )
    try:
        return float(value)
    except OverflowError:  # an int beyond float64
        raise DataError(f"{name}={value!r} is beyond float64: samples must be finite") from None


# ---------------------------------------------------------------- kernels
def specialise_rels(*, na: int, nb: int, nc: int, delay: int = 1) -> None:
    """Compile the RELS/RML loop specialised to these orders, for this and later runs.

    :func:`rels` and :class:`RelsEstimator` run a loop compiled for any orders; one
    compiled for a given (na, nb, nc, delay), with them as constants, runs the same
    operations 1.2–1.6× as fast (BENCHMARKS.md) and gives the same results bit for
    bit. Compiling it costs as much as compiling the generic loop (seconds, once: it
    is kept in numba's cache on disk, where later processes find it without being
    asked), so it pays for long records and long-running estimators only.

    Parameters
    ----------
    na, nb, nc, delay : int
        The orders, as in :func:`rels`.

    Examples
    --------
    >>> specialise_rels(na=2, nb=1, nc=1, delay=1)  # doctest: +SKIP
    """
    o = ArmaxOrders(na=na, nb=nb, nc=nc, delay=delay)
    _k.kernel_for(o.na, o.nb, o.nc, o.delay, compile_now=True)


# ---------------------------------------------------------------- batch
def rels(
    u: Any,
    y: Any,
    *,
    theta0: Any = None,
    passes: int = 1,
    settings: RelsSettings | None = None,
    **keywords: Unpack[RelsKeywords],
) -> ArmaxModel:
    """Identify an ARMAX model from a whole record with RELS, eqs (19)–(22), or RML.

    Parameters
    ----------
    u, y : array_like, shape (n_samples,)
        Input and output, finite.
    na, nb, nc : int
        Orders of A (≥ 1), B and C (≥ 0); b has nb + 1 coefficients.
    delay : int
        Input delay d ≥ 0 (use d ≥ 1 for sampled-data loops, PAPER.md §5).
    forgetting : float
        λ in (0, 1].
    p0 : float
        α of P(0) = α I, on the internally RMS-normalised data.
    p0_c : float, optional
        Initial P of the c-part (P(0) = diag(α…, α_c…)); default α, the paper's αI.
        On oversampled band-limited data use a large α (1e10: P(0) acts as a ridge
        1/α that biases high orders) with a moderate α_c (1e2): a huge α_c lets the
        near-zero early a-posteriori residuals drive C to its bound (RELS start-up
        divergence). See the test-suite's 2nd–6th-order cases.
    theta0 : array_like, shape (na+nb+1+nc,), optional
        Initial θ̂ in physical units (default zeros).
    dt : float
        Sample period (s).
    passes : int
        Number of passes over the record; each later pass restarts the regressor at
        zero and P at P(0) but keeps θ̂ (helps the C-part converge on short records).
    trace_bound : float, optional
        Upper bound of tr P (default tr P(0)).
    c_radius : float
        Roots of C are kept inside this radius.
    method : {"rels", "rml"}
        "rels": the paper's eqs (19)–(22). "rml": recursive maximum likelihood (the
        recursive prediction-error method for ARMAX, Ljung & Söderström 1983): gain
        and P update from the regressor filtered through 1/Ĉ (see the module notes).
        Use "rml" with nc = na when the disturbance is mostly white noise at the
        output (output-error records), where RELS is biased. With nc = 0 both are RLS.
    settings : RelsSettings, optional
        All the above but ``theta0`` and ``passes`` in one checked object, instead of
        the keywords.

    Returns
    -------
    ArmaxModel
        ``noise_variance`` is the mean of ξ̂² over the second half of the last pass;
        ``covariance`` is σ² P (meaningful for λ = 1; for RML P approximates the
        inverse Hessian of the prediction-error loss, the usual PEM covariance);
        ``meta`` holds method, n_samples, forgetting, p0, passes, resets,
        c_projections, trace_scalings, u_scale, y_scale.

    Raises
    ------
    DataError
        Non-1-D, unequal-length, non-finite or too short records, or u and y so far
        apart in magnitude that b = b_scaled·RMS(y)/RMS(u) leaves float64 (any common
        magnitude works: the record is scaled by its RMS, formed without overflow).
    TypeError
        Orders or settings of the wrong type (``na=1.5``, ``p0="big"``).
    ParameterError
        Impossible orders or settings.
    IdentificationError
        If the estimate cannot be expressed in physical units.

    Warns
    -----
    EhssWarning
        When the identified model is unstable.

    Examples
    --------
    >>> import numpy as np
    >>> from scipy.signal import lfilter
    >>> u = np.random.default_rng(0).standard_normal(2000)
    >>> y = lfilter([0, 0.5], [1, -0.8], u)
    >>> m = rels(u, y, na=1, nb=0, nc=0, delay=1)
    >>> np.round(m.a, 6).tolist(), np.round(m.b, 6).tolist()
    ([1.0, -0.8], [0.5])
    """
    s = rels_settings(settings, keywords)
    passes = check_int(passes, "passes", lo=1)
    theta0 = check_theta0(theta0, s.n_params)
    u, y = as_record(u, y)
    too_short(u.size, s)
    su, sy, dvec = record_scales(u, y, s)
    us, ys = u / su, y / sy
    theta_s = theta0 / dvec
    kernel = s.kernel()
    hist = np.empty((0, s.n_params))
    run = _k.kernel_for(s.na, s.nb, s.nc, s.delay)
    totals = dict.fromkeys(_k.COUNTER_NAMES, 0)
    rec = _k.record(us, ys)
    xi = rec[3]  # ξ̂ of the last pass
    for _ in range(passes):
        block, views = new_state(kernel, theta_s)
        run(block, rec, hist, 1, True)
        totals = {key: totals[key] + v for key, v in block_counters(block).items()}
        theta_s = views.theta.copy()
    totals.pop("n_samples")
    nv_s = float(np.mean(np.square(xi[u.size // 2 :])))
    meta = {"method": s.method, "n_samples": int(u.size), **s.meta(passes), "u_scale": su,
            "y_scale": sy, **totals}
    model = model_from_state(views, s, su, sy, nv_s, meta)
    model.check(warn=True)
    return model


# ---------------------------------------------------------------- streaming
class RelsEstimator:
    """Streaming RELS (eqs 19–22) or RML: one sample at a time, the same safeguards.

    Parameters
    ----------
    na, nb, nc, delay, forgetting, p0, theta0, dt
        As in :func:`rels` (θ0 in physical units).
    trace_bound : float, optional
        Upper bound of tr P (default tr P(0)).
    p0_c : float, optional
        Initial P of the c-part (default ``p0``); see :func:`rels`.
    history_every : int, optional
        Record θ̂ (physical units) every this many samples in :attr:`history`.
    u_scale, y_scale : float
        A stream has no whole record to take an RMS from: give the expected size of u
        and y (e.g. the command range and the sensor range) so that the estimator
        works on ``u/u_scale`` and ``y/y_scale``, where α = p0 is meaningful. Default 1
        (no scaling). The results (:attr:`theta`, :attr:`model`, :meth:`update`'s
        prediction error) are in physical units.
    c_radius : float
        Roots of C are kept inside this radius.
    method : {"rels", "rml"}
        As in :func:`rels`: the paper's RELS, or recursive maximum likelihood (RPEM
        for ARMAX, Ljung & Söderström 1983) for output-error-like disturbances.
    settings : RelsSettings, optional
        The orders and settings (all the above but ``theta0``, ``history_every``,
        ``u_scale`` and ``y_scale``) in one checked object, instead of the keywords.

    Notes
    -----
    :meth:`update` and :meth:`update_many` run the same compiled loop as :func:`rels`
    (a run of one sample per call, or of the whole block); :attr:`P` is in scaled
    units. :meth:`update` calls the loop compiled for its one signature directly
    (numba's ``Dispatcher.compile`` returns that entry point), so a call does not pay
    the dispatcher's typing of its arguments, and passes its sample through the
    block's own record (``io``, written and read through a memoryview). The loop is
    the one specialised to the orders when :func:`specialise_rels` has compiled it
    (in this process or an earlier one: numba's cache), else the generic one; both
    give the same results, bit for bit.

    Examples
    --------
    >>> est = RelsEstimator(na=1, nb=0, nc=0, delay=1)
    >>> e = est.update(1.0, 0.0)
    """

    def __init__(
        self,
        *,
        theta0: Any = None,
        history_every: int | None = None,
        u_scale: float = 1.0,
        y_scale: float = 1.0,
        settings: RelsSettings | None = None,
        **keywords: Unpack[RelsKeywords],
    ) -> None:
        s = self._settings = rels_settings(settings, keywords)
        self._us, self._ys = (check_real(v, name, lo=0.0, lo_open=True)
                              for name, v in (("u_scale", u_scale), ("y_scale", y_scale)))
        self._dvec = theta_scale(s.na, s.nb, s.nc, self._us, self._ys)
        self._theta0 = check_theta0(theta0, s.n_params)
        if history_every is not None:
            history_every = check_int(history_every, "history_every", lo=1)
        self._every = history_every
        self._run = _k.kernel_for(s.na, s.nb, s.nc, s.delay)
        self._no_hist = np.empty((0, s.n_params))
        self.reset()

    @property
    def settings(self) -> RelsSettings:
        """The orders and settings of the estimator."""
        return self._settings

    # ---------------------------------------------------------------- state
    def reset(self) -> None:
        """Back to θ̂(0), P(0), empty regressor, counters and history cleared."""
        kernel = self._settings.kernel(u_scale=self._us, y_scale=self._ys)
        block, _ = new_state(kernel, self._theta0 / self._dvec)
        self._attach(block)
        self._hist: list[np.ndarray] = []
        self._since = 0
        if self._every is not None:
            self.update = self._update_with_history  # type: ignore[method-assign]

    def _attach(self, block: np.ndarray) -> None:
        """Work on ``block``: its named views, and the streaming sample's record."""
        self._block = block
        self._views = _k.state_views(block)
        self._io_rec = self._views.io.reshape((4, 1))
        # a memoryview of the float64 io: u, y written and e read per sample
        self._io: Any = self._views.io.data

    def __getstate__(self) -> dict[str, Any]:
        # the views and the memoryview are rebuilt on the copy's own block, and the
        # compiled loop is looked up again (a copy, a deep copy or a pickle)
        state = {k: v for k, v in self.__dict__.items()
                 if k not in ("_views", "_io_rec", "_io", "_run", "update")}
        state["_history_update"] = "update" in self.__dict__
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        history_update = state.pop("_history_update")
        block = state.pop("_block")
        self.__dict__.update(state)
        s = self._settings
        self._run = _k.kernel_for(s.na, s.nb, s.nc, s.delay)
        self._attach(_k.aligned_copy(block))
        self._hist = list(self._hist)  # a shallow copy too keeps its own history
        if history_update:
            self.update = self._update_with_history  # type: ignore[method-assign]

    def freeze(self) -> None:
        """Stop adapting: θ̂ and P are held, regressors and residuals still run."""
        self.enabled = False

    def unfreeze(self) -> None:
        """Resume adapting."""
        self.enabled = True

    @property
    def enabled(self) -> bool:
        """True while the estimator adapts (see :meth:`freeze`)."""
        return bool(self._block[_k.ENABLED])

    @enabled.setter
    def enabled(self, value: bool) -> None:
        _k.set_enabled(self._block, bool(value))

    # ---------------------------------------------------------------- following a change
    @property
    def trace_bound(self) -> float:
        """The bound of tr P as the estimator runs now (see :meth:`set_trace_bound`)."""
        return self._settings.trace_max

    def set_trace_bound(self, trace_bound: float | None) -> None:
        """Bound tr P by ``trace_bound`` (None: tr P(0)) from the next sample on.

        Under poor excitation the bound holds P in the directions the data do not
        excite, and its scaling, every sample, also cancels the forgetting in the
        excited ones: the estimator then follows a change slowly. A bound far above
        tr P lets λ act (the estimator follows within about its memory, with more
        scatter); brought back down, P is scaled to it at once. The last sample's
        pending P update is applied first; θ̂ and the regressors are kept.

        Raises
        ------
        TypeError, ParameterError
            If ``trace_bound`` is not a real number > 0 (nothing changes).
        """
        settings = dataclasses.replace(self._settings, trace_bound=trace_bound)  # checks it
        self._settle()
        self._settings = settings
        bound = settings.trace_max
        self._block[_TRACE_MAX] = bound
        P = self._views.P  # noqa: N806 - the paper's symbol
        trace = float(np.trace(P))
        if trace > bound:
            P *= bound / trace

    @property
    def forgetting(self) -> float:
        """λ as the estimator runs now (see :meth:`set_forgetting`)."""
        return self._settings.forgetting

    def set_forgetting(self, forgetting: float) -> None:
        """Run on with the forgetting factor λ = ``forgetting`` from the next sample on.

        λ enters the gain (21), K(k) = P(k−1)ψ̂(k) / (λ + ψ̂ᵀ(k)P(k−1)ψ̂(k)), and the
        update (22), P(k) = [I − K(k)ψ̂ᵀ(k)]P(k−1)/λ, so that θ̂ (20) weighs the sample
        k − j by λʲ: a memory of about 1/(1 − λ) samples. A long memory scatters less
        in steady running; a short one follows a change of the system faster (variable
        forgetting: switched to the short memory when a change is detected, back once
        it is followed). The last sample's pending P update is applied first, with the
        λ it was computed with; θ̂, P and the regressors are kept. The running mean of
        ξ̂² then runs over the new memory.

        Raises
        ------
        TypeError, ParameterError
            If ``forgetting`` is not a real number in (0, 1] (nothing changes).
        """
        settings = dataclasses.replace(self._settings, forgetting=forgetting)  # checks it
        self._settle()
        self._settings = settings
        self._block[_LAM] = settings.forgetting

    def set_covariance(self, P: np.ndarray) -> None:  # noqa: N803 - the paper's symbol
        """Run on from ``P`` (scaled units, as :attr:`P` gives it), θ̂ and the
        regressors kept: e.g. a P read earlier, to take up the gain the estimator had
        then. ``P`` must be symmetric positive definite; it is scaled down to
        :attr:`trace_bound` if its trace exceeds it, as each update's is.

        Raises
        ------
        DataError
            If ``P`` has the wrong shape, is not finite, not symmetric or not positive
            definite (nothing changes).
        """
        n = self._settings.n_params
        P = np.array(P, dtype=float)  # noqa: N806
        if P.shape != (n, n) or not np.all(np.isfinite(P)):
            raise DataError(f"P of shape {P.shape} must be a finite ({n}, {n}) array")
        if not np.array_equal(P, P.T) or np.any(np.linalg.eigvalsh(P) <= 0.0):
            raise DataError("P must be symmetric positive definite")
        self._settle()
        self._views.P[:] = P * min(1.0, self._settings.trace_max / float(np.trace(P)))

    # ---------------------------------------------------------------- updates
    def update(self, u_k: float, y_k: float) -> float:
        """Process one sample; return the a-priori prediction error y(k) − ψ̂ᵀθ̂(k−1).

        An error that overflows float64 (adversarial magnitudes) is returned as 0.0,
        the sample does not update θ̂ and it is counted in ``counters["skipped"]``.

        Raises
        ------
        TypeError
            If ``u_k`` or ``y_k`` is not a real number (arrays, complex, strings, None,
            bool); use :meth:`update_many` for blocks.
        DataError
            If ``u_k`` or ``y_k`` is not finite (the state is then left unchanged).
        """
        if type(u_k) is not float or type(y_k) is not float:
            u_k, y_k = _sample("u_k", u_k), _sample("y_k", y_k)
        io = self._io
        io[0] = u_k
        io[1] = y_k
        if not self._run(self._block, self._io_rec, self._no_hist, 1, False):
            raise DataError(f"u_k={u_k!r}, y_k={y_k!r}: samples must be finite (also "
                            f"once divided by u_scale={self._us!r}, y_scale={self._ys!r})")
        return io[2]  # e(k), in y's units: the kernel applies the scales

    def _update_with_history(self, u_k: float, y_k: float) -> float:
        e = RelsEstimator.update(self, u_k, y_k)
        self._since += 1
        if self._since == self._every:
            self._since = 0
            self._hist.append(self.theta)
        return e

    def update_many(self, u: Any, y: Any) -> np.ndarray:
        """Process a block of samples; return their a-priori prediction errors."""
        u, y = as_record(u, y)
        if self._every is None:
            rec = _k.record(u, y)
            self._run_record(rec, self._no_hist, 1)
            return rec[2].copy()
        # the kernel records every `every` samples from its own start: run the first
        # (every − since) samples one by one to keep the phase
        err = np.empty(u.size)
        first = min(u.size, self._every - self._since)
        for k in range(first):
            err[k] = self.update(u[k], y[k])
        rest = u.size - first
        hist = np.empty((rest // self._every, self._settings.n_params))
        if rest:  # else the samples above counted themselves (_update_with_history)
            rec = _k.record(u[first:], y[first:])
            self._run_record(rec, hist, self._every)
            err[first:] = rec[2]
            self._since = rest % self._every
        self._hist.extend(list(hist * self._dvec))
        return err

    def _run_record(self, rec: np.ndarray, hist: np.ndarray, every: int) -> None:
        """Run a (4, N) record (see ``_kernels.rels_run``) and settle P."""
        done = self._run(self._block, rec, hist, every, True)
        if done < rec.shape[1]:
            raise DataError(
                f"sample {done} is not finite once divided by u_scale={self._us!r}, "
                f"y_scale={self._ys!r} (the {done} samples before it were run)"
            )

    # ---------------------------------------------------------------- results
    def _settle(self) -> None:
        """Apply the last sample's pending P update (a run of no samples)."""
        self._run(self._block, np.empty((4, 0)), self._no_hist, 1, True)

    @property
    def theta(self) -> np.ndarray:
        """Current θ̂ = [a1..a_na, b0..b_nb, c1..c_nc] in physical units (a copy)."""
        return self._views.theta * self._dvec

    @property
    def P(self) -> np.ndarray:  # noqa: N802 - the paper's symbol
        """Current P(k) (a copy, in the scaled units the estimator works in)."""
        self._settle()
        return self._views.P.copy()

    @property
    def history(self) -> np.ndarray:
        """θ̂ every ``history_every`` samples, shape (n_records, n_params)."""
        if not self._hist:
            return np.empty((0, self._settings.n_params))
        return np.array(self._hist)

    @property
    def counters(self) -> dict[str, int]:
        """n_samples, resets, c_projections, trace_scalings, skipped."""
        self._settle()  # the pending P update's guards may count
        return block_counters(self._block)

    @property
    def model(self) -> ArmaxModel:
        """The current estimate as an :class:`ArmaxModel` (no stability warning)."""
        s = self._settings
        self._settle()
        meta = {"method": f"{s.method}-streaming", **s.meta(), "u_scale": self._us,
                "y_scale": self._ys, **block_counters(self._block)}
        return model_from_state(self._views, s, self._us, self._ys,
                                float(self._block[_k.NOISE_VAR]), meta)
