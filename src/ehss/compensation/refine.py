"""Iterative refinement of a compensated drive on the simulated rig.

Each iteration runs the loop with the current drive, re-identifies the closed loop from
drive → output (RELS, same orders and delay as the starting model), rebuilds the inverse
and corrects the drive with a learning update (iterative learning control):

.. math:: u_{k+1} = u_k + L\\,F_k\\,(r - y_k)

with ``F_k`` the band-limited inverse of the model identified on iteration ``k`` and
``L`` the learning gain. With ``G F_k ≈ 1`` in the band the error contracts by
``|1 - L G F_k|`` per iteration, so model errors of the one-shot inverse ``u_0 = F_0 r``
are corrected by measurement instead of being left in the tracking error.

If the model was identified behind known factors ``F`` (e.g. the acceleration loop's
generator and accelerometer coupling, :mod:`ehss.identification.known`), each
re-identification is done behind them too (from ``F u_k`` to ``y_k``) and every inverse is
``G_rest^{-1} ∘ F^{-1}`` (:mod:`ehss.compensation.inverse`).

The loop is the simulated rig by default; any callable ``drive -> output`` can stand in
for it (a real rig's run, or a test plant).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.signal

from ehss.compensation.inverse import InverseModel, _as_reference, design_inverse
from ehss.errors import ParameterError

__all__ = ["RefineResult", "refine", "rms", "DriveUpdate", "update_drive"]


def rms(x: np.ndarray) -> float:
    """Root mean square."""
    x = np.asarray(x, dtype=float)
    return float(np.sqrt(np.mean(x * x)))


@dataclass(frozen=True, kw_only=True)
class RefineResult:
    """Outcome of :func:`refine`.

    Attributes
    ----------
    drive : ndarray
        The best drive found (lowest RMS tracking error).
    drives, outputs : list of ndarray
        Drive and measured output of each simulated iteration (``iterations + 1`` runs).
    rms_error : ndarray
        RMS of ``output - reference`` per run (SI units of the loop).
    models : list
        The model used for the inverse of each run (the first is the one given; with
        known factors, the identified rest behind them).
    inverses : list of InverseModel
    """

    drive: np.ndarray = field(repr=False)
    drives: list = field(repr=False)
    outputs: list = field(repr=False)
    rms_error: np.ndarray
    models: list = field(repr=False)
    inverses: list = field(repr=False)


def refine(
    loop: str | Callable[[np.ndarray], np.ndarray],
    reference: Any,
    *,
    params: Any = None,
    model: Any,
    iterations: int = 3,
    method: str = "zpetc",
    band_hz: tuple[float, float] | None = None,
    learning_gain: float = 1.0,
    reidentify: bool = True,
    seed: int | None = 0,
    nc: int | None = None,
    known: tuple[Any, Any] | None = None,
) -> RefineResult:
    """Refine a compensated drive by simulation, re-identification and learning updates.

    Parameters
    ----------
    loop : {"position", "acceleration", "force"} or callable
        Loop of the simulated rig, or a function ``drive -> measured output`` (same
        length) that runs the loop.
    reference : array_like, shape (n_samples,)
        Desired output (SI), at the control rate of ``params``.
    params : RigParams, optional
    model : ArmaxModel
        Closed-loop model to start from (its orders and delay are reused).
    iterations : int
        Number of learning updates (``iterations + 1`` simulations).
    method, band_hz
        Inverse design (see :func:`~ehss.compensation.inverse.design_inverse_tf`).
    learning_gain : float
        ``L`` of the update law, in (0, 2).
    reidentify : bool
        Re-identify the loop from each run's drive → output (default); otherwise keep
        the first inverse.
    seed : int, optional
        Sensor-noise seed of the first run (``seed + k`` for run ``k``).
    nc : int, optional
        Noise order for re-identification (default: the model's).
    known : (num, den), optional
        Known factor in series with ``model`` (see
        :func:`~ehss.compensation.inverse.design_inverse_tf`); a model from
        :func:`ehss.identification.known.compose` carries its own.

    Returns
    -------
    RefineResult
    """
    from ehss.simulation import simulate

    if isinstance(iterations, bool) or not isinstance(iterations, (int, np.integer)) \
            or iterations < 0:
        raise ParameterError(f"iterations={iterations!r} must be an integer >= 0")
    if not 0.0 < learning_gain < 2.0:
        raise ParameterError(f"learning_gain={learning_gain!r} must be in (0, 2)")
    r = _as_reference(reference)
    inverse: InverseModel = design_inverse(model, method=method, band_hz=band_hz, known=known)
    na, nb = model.na, model.nb
    if inverse.has_known:
        known = (inverse.known_num, inverse.known_den)
        if _composed(model, known):
            # Re-identification is behind the known factor: the rest's orders.
            na, nb = na - (known[1].size - 1), nb - (known[0].size - 1)

    def run(drive: np.ndarray, k: int) -> np.ndarray:
        if callable(loop):
            y = np.asarray(loop(drive), dtype=float)
            if y.shape != drive.shape:
                raise ParameterError(
                    f"loop returned shape {y.shape} for a drive of shape {drive.shape}")
            return y
        run_seed = None if seed is None else seed + k
        return simulate(loop, drive, params=params, seed=run_seed).output

    # u_0 = F_0 r: the one-shot compensation.
    drive = inverse.apply(r)
    drives, outputs, errors, models, inverses = [], [], [], [model], [inverse]
    for k in range(iterations + 1):
        y = run(drive, k)
        drives.append(drive)
        outputs.append(y)
        errors.append(rms(y - r))
        if k == iterations:
            break
        step = update_drive(
            models[-1], r, drive, y, inverse=inverse, method=method, band_hz=band_hz,
            learning_gain=learning_gain, reidentify=reidentify, nc=nc, known=known,
            orders=(na, nb),
        )
        drive, inverse = step.drive, step.inverse
        models.append(step.model)
        inverses.append(inverse)
    best = int(np.argmin(errors))
    return RefineResult(drive=drives[best], drives=drives, outputs=outputs,
                        rms_error=np.asarray(errors), models=models, inverses=inverses)


@dataclass(frozen=True, kw_only=True)
class DriveUpdate:
    """One learning update of a drive file (see :func:`update_drive`)."""

    drive: np.ndarray
    model: Any
    inverse: InverseModel
    rms_error: float


def update_drive(
    model: Any,
    reference: Any,
    drive: Any,
    output: Any,
    *,
    inverse: InverseModel | None = None,
    method: str = "zpetc",
    band_hz: tuple[float, float] | None = None,
    learning_gain: float = 1.0,
    reidentify: bool = False,
    nc: int | None = None,
    known: tuple[Any, Any] | None = None,
    orders: tuple[int, int] | None = None,
) -> DriveUpdate:
    """One drive-file iteration from a measured run: u⁺ = u + L F (r − y).

    This is the step a rig user takes between test runs: play ``drive``, record
    ``output``, then correct the drive with the inverse ``F`` of the closed-loop model —
    of ``model``, or, with ``reidentify``, of a model re-identified (RELS, the model's
    orders and delay) from this run's drive → output.

    Parameters
    ----------
    model : ArmaxModel
        Closed-loop model (reference → output).
    reference, drive, output : array_like, shape (n_samples,)
        Desired output, the drive that was played, and the measured output.
    inverse : InverseModel, optional
        The inverse of ``model`` if already designed.
    learning_gain : float
        ``L`` in (0, 2).

    Returns
    -------
    DriveUpdate
        The next drive, the model and inverse used, and the RMS error of this run.
    """
    from ehss.identification.rels import rels

    if not 0.0 < learning_gain < 2.0:
        raise ParameterError(f"learning_gain={learning_gain!r} must be in (0, 2)")
    r = _as_reference(reference)
    u = _as_reference(drive)
    y = _as_reference(output)
    if not r.size == u.size == y.size:
        raise ParameterError(
            f"reference, drive and output must have the same length, got {r.size}, "
            f"{u.size} and {y.size}"
        )
    if inverse is None:
        inverse = design_inverse(model, method=method, band_hz=band_hz, known=known)
    if inverse.has_known:
        known = (inverse.known_num, inverse.known_den)
    used = model
    if reidentify:
        na, nb = (model.na, model.nb) if orders is None else orders
        if orders is None and known is not None and _composed(model, known):
            na, nb = na - (known[1].size - 1), nb - (known[0].size - 1)
        u_id = u if known is None else scipy.signal.lfilter(known[0], known[1], u)
        try:
            new = rels(u_id, y, na=na, nb=nb, nc=model.nc if nc is None else nc,
                       delay=model.delay, dt=model.dt)
            inverse = design_inverse(new, method=method, band_hz=band_hz, known=known)
            used = new
        except ParameterError:
            pass  # an unusable re-identification (e.g. unstable): keep the inverse
    # u_{k+1} = u_k + L F_k (r - y_k)
    new_drive = u + learning_gain * inverse.apply(r - y)
    return DriveUpdate(drive=new_drive, model=used, inverse=inverse, rms_error=rms(y - r))


def _composed(model: Any, known: tuple[np.ndarray, np.ndarray]) -> bool:
    """Whether ``model`` is a complete model carrying ``known`` (from ``compose``)."""
    stored = (getattr(model, "meta", None) or {}).get("known_factors")
    return stored is not None and len(stored["num"]) == known[0].size \
        and len(stored["den"]) == known[1].size
