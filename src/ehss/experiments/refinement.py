"""Drive-file iteration of a compensated drive on a plant: the simulated rig or any run.

:func:`refine` plays the one-shot drive of an inverse model
(:func:`ehss.compensation.compensate`, stable inversion in the model's validated band by
default), then repeats what a rig user does between test runs: correct the drive from
the measured output (:func:`ehss.compensation.update_drive`: a band-limited learning
update with a gain chosen from the run, refused and halved when the error grows) and play
it again. The plant is passed in: a loop of the simulated rig (``"position"``, ...) with
its parameter set, or any callable ``drive -> measured output``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ehss._checks import check_int
from ehss.compensation import (
    DEFAULT_MAX_GAIN,
    InverseModel,
    as_reference,
    compensate,
    design_inverse,
    run_record,
    update_drive,
)
from ehss.errors import ParameterError

__all__ = ["RefineResult", "refine", "rms"]


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
        Drive and measured output of each run (up to ``iterations + 1`` runs).
    rms_error : ndarray
        RMS of ``output - reference`` per run (SI units of the loop).
    records : list of RunRecord
        Per-run log (RMS and peak error, normalised error, J1 lag, drive gain).
    gains : list of float
        Learning gain of each update.
    accepted : list of bool
        Per updated run: whether run ``k`` improved on the run its drive was built from
        and so became the base of the next update (run 0 always; False: refused, the
        next drive backs off with half the gain).
    stopped : bool
        The iteration stopped: the error kept growing, or (with ``stop_without_gain``) no
        learning gain was stable for the model error the first run showed.
    message : str
        Why it stopped ("" if it did not).
    models : list
        The model used for each update's inverse (the first is the one given).
    inverses : list of InverseModel
    """

    drive: np.ndarray = field(repr=False)
    drives: list = field(repr=False)
    outputs: list = field(repr=False)
    rms_error: np.ndarray
    records: list = field(repr=False)
    gains: list
    accepted: list
    stopped: bool
    message: str
    models: list = field(repr=False)
    inverses: list = field(repr=False)


def refine(
    loop: str | Callable[[np.ndarray], np.ndarray],
    reference: Any,
    *,
    model: Any,
    fs: float | None = None,
    params: Any = None,
    iterations: int = 2,
    method: str = "stable",
    update: str = "model",
    band_hz: tuple[float, float] | None = None,
    learning_gain: float | None = None,
    reidentify: bool = False,
    seed: int | None = 0,
    nc: int | None = None,
    known: tuple[Any, Any] | None = None,
    first_drive: np.ndarray | None = None,
    max_gain: float | None = DEFAULT_MAX_GAIN,
    stop_without_gain: bool = False,
) -> RefineResult:
    """Refine a compensated drive by running the plant and correcting the drive.

    Parameters
    ----------
    loop : {"position", "acceleration", "force"} or callable
        Loop of the simulated rig (with ``params``), or a function ``drive -> measured
        output`` (same length) that runs the plant.
    reference : ehss.signals.Signal, or array_like with ``fs``
        Desired output (SI), at rest at both ends, at the model's rate or an integer
        multiple of it.
    fs : float, optional
        Sample rate of an array reference; default the model's (``1 / model.dt``).
    model : ArmaxModel
        Closed-loop model (band: ``band_hz`` or its validated band).
    params : RigParams, optional
    iterations : int
        Number of learning updates (``iterations + 1`` runs at most).
    method : {"stable", "zpetc", "zmetc"}
        Inverse design of the one-shot drive and of the model-based update.
    update : {"model", "frf"}
        Inverse used by the learning update (:func:`ehss.compensation.update_drive`).
    band_hz : (lo, hi), optional
    learning_gain : float, optional
        Fixed gain; default chosen from the first run.
    reidentify : bool
        Re-identify the loop from each run before inverting it.
    seed : int, optional
        Sensor-noise seed of the first run (``seed + k`` for run ``k``).
    nc : int, optional
        Noise order for re-identification (default: the model's).
    known : (num, den), optional
        Known factor in series with ``model``.
    first_drive : ndarray, optional
        Drive of the first run instead of the one-shot inverse (e.g. the reference
        itself, as a non-parametric iteration starts).
    max_gain : float or None
        Bound of the one-shot drive's gain (:func:`ehss.compensation.check_drive`).
    stop_without_gain : bool
        When the first run shows no stable default learning gain, stop with the one-shot
        drive (``stopped``, ``message``) instead of raising ParameterError.

    Returns
    -------
    RefineResult
    """
    from ehss.simulation import simulate

    iterations = check_int(iterations, "iterations", lo=0)
    from ehss.signals import Signal

    if fs is None and not isinstance(reference, Signal):
        fs = 1.0 / model.dt
    r, fs = as_reference(reference, fs)
    band = band_hz if band_hz is not None else model.band_hz
    inverse: InverseModel = design_inverse(model, method=method, band_hz=band, known=known)

    def run(drive: np.ndarray, k: int) -> np.ndarray:
        if callable(loop):
            y = np.asarray(loop(drive), dtype=float)
            if y.shape != drive.shape:
                raise ParameterError(
                    f"loop returned shape {y.shape} for a drive of shape {drive.shape}")
            return y
        run_seed = None if seed is None else seed + k
        return simulate(loop, drive, params=params, fs=fs, seed=run_seed).output

    if first_drive is None:
        drive = compensate(inverse, r, fs=fs, max_gain=max_gain)
    else:
        drive = np.asarray(first_drive, dtype=float)
    drives, outputs, records, gains, accepted = [], [], [], [], []
    models, inverses = [model], [inverse]
    state, stopped, message = None, False, ""
    current_model = model
    for k in range(iterations + 1):
        y = run(drive, k)
        drives.append(drive)
        outputs.append(y)
        if k == iterations:
            records.append(run_record(r, drive, y))
            break
        try:
            step = update_drive(
                r, drive, y, fs=fs, model=current_model, method=update,
                inverse=inverses[-1] if update == "model" and not reidentify else None,
                inverse_method=method,
                band_hz=band, gain=learning_gain if state is None else None, state=state,
                reidentify=reidentify, nc=nc, known=known)
        except ParameterError as exc:
            if learning_gain is not None or state is not None or not stop_without_gain:
                raise
            # No gain the run shows to be stable: keep the drive played, iterate no more.
            records.append(run_record(r, drive, y))
            stopped, message = True, str(exc)
            break
        records.append(step.record)
        if step.stopped:
            stopped, message = True, step.message
            break
        gains.append(step.gain)
        accepted.append(step.accepted)
        state = step.state
        drive = step.drive
        if step.model is not None:
            current_model = step.model
        models.append(current_model)
        if step.inverse is not None:
            inverses.append(step.inverse)
    errors = np.array([rec.rms_error for rec in records])
    best = int(np.argmin(errors))
    return RefineResult(drive=drives[best], drives=drives, outputs=outputs,
                        rms_error=errors, records=records, gains=gains, accepted=accepted,
                        stopped=stopped, message=message, models=models,
                        inverses=inverses)
