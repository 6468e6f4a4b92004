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
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from ehss._checks import check_int
from ehss.compensation import (
    DEFAULT_MAX_GAIN,
    DriveUpdate,
    InverseModel,
    IterationState,
    RunRecord,
    UpdateOptions,
    as_reference,
    compensate,
    design_inverse,
    run_record,
    update_drive,
)
from ehss.errors import ParameterError
from ehss.workflow.options import or_default

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
    options: UpdateOptions | None = None,
    seed: int | None = 0,
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
    model : ArmaxModel
        Closed-loop model (band: the options' ``band_hz`` or its validated band).
    fs : float, optional
        Sample rate of an array reference; default the model's (``1 / model.dt``).
    params : RigParams, optional
    iterations : int
        Number of learning updates (``iterations + 1`` runs at most).
    options : UpdateOptions, optional
        The learning update (:func:`ehss.compensation.update_drive`); its
        ``inverse_method``, ``band_hz`` and ``known`` design the one-shot drive too, and
        its ``gain`` is the first update's (later ones keep or halve it).
    seed : int, optional
        Sensor-noise seed of the first run (``seed + k`` for run ``k``).
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
    from ehss.signals import Signal

    iterations = check_int(iterations, "iterations", lo=0)
    opts = or_default(options, UpdateOptions, "options")
    if fs is None and not isinstance(reference, Signal):
        fs = 1.0 / model.dt
    r, fs = as_reference(reference, fs)
    band = opts.band_hz if opts.band_hz is not None else model.band_hz
    opts = replace(opts, band_hz=band)
    inverse: InverseModel = design_inverse(model, method=opts.inverse_method, band_hz=band,
                                           known=opts.known)
    run = _plant(loop, params, fs, seed)
    if first_drive is None:
        drive = compensate(inverse, r, fs=fs, max_gain=max_gain)
    else:
        drive = np.asarray(first_drive, dtype=float)
    log = _Log(model, inverse)
    state: IterationState | None = None
    for k in range(iterations + 1):
        y = run(drive, k)
        log.played(drive, y)
        if k == iterations:
            log.records.append(run_record(r, drive, y))
            break
        reuse = opts.method == "model" and not opts.reidentify
        try:
            step = update_drive(r, drive, y, fs=fs, model=log.models[-1],
                                inverse=log.inverses[-1] if reuse else None, state=state,
                                options=opts if state is None else replace(opts, gain=None))
        except ParameterError as exc:
            if opts.gain is not None or state is not None or not stop_without_gain:
                raise
            # No gain the run shows to be stable: keep the drive played, iterate no more.
            log.records.append(run_record(r, drive, y))
            log.stop(str(exc))
            break
        if log.updated(step):
            break
        state, drive = step.state, step.drive
    return log.result()


def _plant(loop: str | Callable[[np.ndarray], np.ndarray], params: Any, fs: float,
           seed: int | None) -> Callable[[np.ndarray, int], np.ndarray]:
    """``(drive, k) -> output`` of run ``k``: the simulated rig's loop (seed ``seed + k``)
    or the callable given, its output checked for shape."""
    from ehss.simulation import simulate

    def run(drive: np.ndarray, k: int) -> np.ndarray:
        if callable(loop):
            y = np.asarray(loop(drive), dtype=float)
            if y.shape != drive.shape:
                raise ParameterError(
                    f"loop returned shape {y.shape} for a drive of shape {drive.shape}")
            return y
        run_seed = None if seed is None else seed + k
        return simulate(loop, drive, params=params, fs=fs, seed=run_seed).output

    return run


class _Log:
    """What :func:`refine` keeps of each run and update."""

    def __init__(self, model: Any, inverse: InverseModel) -> None:
        self.drives: list[np.ndarray] = []
        self.outputs: list[np.ndarray] = []
        self.records: list[RunRecord] = []
        self.gains: list[float] = []
        self.accepted: list[bool] = []
        self.models: list[Any] = [model]
        self.inverses: list[InverseModel] = [inverse]
        self.stopped, self.message = False, ""

    def played(self, drive: np.ndarray, output: np.ndarray) -> None:
        self.drives.append(drive)
        self.outputs.append(output)

    def stop(self, message: str) -> None:
        self.stopped, self.message = True, message

    def updated(self, step: DriveUpdate) -> bool:
        """Log an update; True when it stopped the iteration."""
        self.records.append(step.record)
        if step.stopped:
            self.stop(step.message)
            return True
        self.gains.append(step.gain)
        self.accepted.append(step.accepted)
        self.models.append(step.model if step.model is not None else self.models[-1])
        if step.inverse is not None:
            self.inverses.append(step.inverse)
        return False

    def result(self) -> RefineResult:
        errors = np.array([rec.rms_error for rec in self.records])
        best = int(np.argmin(errors))
        return RefineResult(drive=self.drives[best], drives=self.drives,
                            outputs=self.outputs, rms_error=errors, records=self.records,
                            gains=self.gains, accepted=self.accepted, stopped=self.stopped,
                            message=self.message, models=self.models,
                            inverses=self.inverses)
