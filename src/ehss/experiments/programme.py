"""The paper's experimental programme on the simulated rig (PAPER.md §6, Figs 12–15).

1. Step tests of the three loops (Fig. 12).
2. Position loop, band-limited random displacement 2–100 Hz, 4th-order model (eq 23 form).
3. Acceleration loop (TVC), random acceleration 0.5 g peak, 2–100 Hz, 6th-order (eq 24 form).
4. Force loop (PID), swept sine 24.25–25.75 kgf, 0–20 Hz, 6th-order (eq 25 form).

Each identification uses the reference as input and the measured feedback as output
(the closed-loop transfer function), RELS on the first part of the record and the rest
held out (:mod:`ehss.experiments.loop_identification`); every model is judged on the
held-out end by :func:`ehss.workflow.assess` and the one
:class:`ehss.workflow.Acceptance`, so the report's verdict is the one ``ehss identify``
prints for the same record, and order selection says which order it would have chosen.
Then feed-forward compensation of the position and acceleration loops.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from concurrent.futures import Executor
from dataclasses import dataclass, field, replace
from functools import partial
from typing import Any

import numpy as np

from ehss import signals
from ehss._checks import check_bool, check_int, check_int_list, check_real
from ehss._warm import warm_up
from ehss.control.known import known_factors
from ehss.errors import DataError, ParameterError
from ehss.experiments.compensation_demo import CompensationDemo, demonstrate
from ehss.experiments.loop_identification import (
    ModelCheck,
    Record,
    convergence,
    identify_and_check,
    loop_record,
    simplest_passing,
)
from ehss.experiments.pool import collect, submit
from ehss.experiments.steps import StepTest, step_tests
from ehss.identification import OrderSelection, select_order
from ehss.linear import closed_loop_radius
from ehss.params import GRAVITY_M_S2, RigParams, preset
from ehss.simulation import SimulationResult, simulate
from ehss.workflow.options import check_fields, option

__all__ = [
    "LoopSetup",
    "ProgrammeSettings",
    "LoopResult",
    "ProgrammeResult",
    "DEFAULT_SETUPS",
    "run_programme",
]

Progress = Callable[[str], None]


@dataclass(frozen=True, kw_only=True)
class LoopSetup:
    """One identification experiment.

    Attributes
    ----------
    loop : str
        ``"position"``, ``"acceleration"`` or ``"force"``.
    orders : tuple of int
        (na, nb, nc, delay) of the paper-form ARMAX model; nb = na − 1 with delay 1 has
        as many numerator coefficients as the paper's equal-degree form, without its
        direct feed-through (PAPER.md §5).
    band_hz : tuple of float
        Excitation band, also the band where the model is validated.
    size : float
        Signal size in SI units: RMS displacement (m), peak acceleration (m/s²), or
        sweep amplitude (N) around ``offset``.
    offset : float
        Static part of the reference (the force test holds 25 kgf).
    """

    loop: str
    orders: tuple[int, int, int, int]
    band_hz: tuple[float, float]
    size: float
    offset: float = 0.0


DEFAULT_SETUPS: dict[str, LoopSetup] = {
    "position": LoopSetup(loop="position", orders=(4, 3, 2, 1), band_hz=(2.0, 100.0), size=1.0e-4),
    "acceleration": LoopSetup(
        loop="acceleration", orders=(6, 5, 2, 1), band_hz=(2.0, 100.0), size=0.5 * GRAVITY_M_S2
    ),
    "force": LoopSetup(
        loop="force",
        orders=(6, 5, 2, 1),
        band_hz=(0.0, 20.0),
        size=0.75 * GRAVITY_M_S2,
        offset=25.0 * GRAVITY_M_S2,
    ),
}


def _duration(value: Any, name: str) -> float:
    if not (math.isfinite(value) and value >= 5.0):
        raise ParameterError(f"{name}={value!r} must be at least 5 s")
    return value


def _holdout(value: Any, name: str) -> float:
    if not 0.05 <= value <= 0.6:
        raise ParameterError(f"{name}={value!r} must be in [0.05, 0.6]")
    return value


def _positive(value: Any, name: str) -> float:
    return check_real(value, name, lo=0.0, lo_open=True)


def _orders(lo: int) -> Callable[[Any, str], tuple[int, ...]]:
    return lambda value, name: tuple(check_int_list(value, name, lo=lo))


def _setups(value: Any, name: str) -> dict[str, LoopSetup]:
    for key, setup in value.items():
        if not isinstance(setup, LoopSetup):
            raise TypeError(f"{name}[{key!r}] must be a LoopSetup, not {type(setup).__name__}")
    return value


@dataclass(frozen=True, kw_only=True)
class ProgrammeSettings:
    """Settings of one run of the programme (all recorded in the report), each checked
    when the settings are made.

    Attributes
    ----------
    seed : int, default 0
    duration_s : float, default 40
        Length of each identification record, at least 5 s.
    step_duration_s : float, default 1
        Length of each step test.
    holdout : float, default 0.3
        Share of each record held out for validation, in [0.05, 0.6].
    forgetting, p0 : float, default 1 and 1e6
        RELS forgetting factor in (0, 1] and initial covariance scale.
    setups : dict of str to LoopSetup, default :data:`DEFAULT_SETUPS`
    order_grid, noise_orders : tuple of int
        The orders na (nb = na − 1) and nc the order selection searches.
    max_search_order : int, default 12
        Highest na searched for a model that meets the acceptance.
    compensation : bool, default True
        Demonstrate the compensation of the position and acceleration loops.
    compensation_duration_s : float, default 16
        Length of each compensation test record, at least 4 s (:func:`ehss.experiments.
        compensation_demo.demonstrate`).
    """

    seed: int = option(0, check=lambda v, n: check_int(v, n, lo=0))
    duration_s: float = option(40.0, check=_duration)
    step_duration_s: float = option(1.0, check=_positive)
    holdout: float = option(0.3, check=_holdout)
    forgetting: float = option(
        1.0, check=lambda v, n: check_real(v, n, lo=0.0, hi=1.0, lo_open=True))
    p0: float = option(1.0e6, check=_positive)
    setups: dict[str, LoopSetup] = field(default_factory=lambda: dict(DEFAULT_SETUPS),
                                         metadata={"check": _setups})
    order_grid: tuple[int, ...] = option((2, 3, 4, 5, 6, 7, 8), check=_orders(1))
    noise_orders: tuple[int, ...] = option((0, 2), check=_orders(0))
    max_search_order: int = option(12, check=lambda v, n: check_int(v, n, lo=1))
    compensation: bool = option(True, check=check_bool)
    compensation_duration_s: float = option(
        16.0, check=lambda v, n: check_real(v, n, lo=4.0, unit="s"))

    def __post_init__(self) -> None:
        check_fields(self)


@dataclass(frozen=True, kw_only=True)
class LoopResult:
    """Everything the report shows for one identified loop.

    ``record`` is the record as identified and validated: its ``band_hz`` is the band the
    models were validated over (the excitation band clipped to [0.5 Hz, 0.45 fs]); with
    ``settings.holdout``, mean removal and no decimation it makes ``ehss identify``'s
    options for the same record.
    """

    setup: LoopSetup
    sim: SimulationResult
    record: Record = field(repr=False)
    paper: ModelCheck
    selection: OrderSelection
    recommended: ModelCheck
    passing: ModelCheck | None
    theta_t: np.ndarray
    theta_history: np.ndarray

    @property
    def passes(self) -> bool:
        return self.paper.passes


@dataclass(frozen=True, kw_only=True)
class ProgrammeResult:
    params: RigParams
    settings: ProgrammeSettings
    steps: dict[str, StepTest]
    loops: dict[str, LoopResult]
    compensation: dict[str, CompensationDemo]
    elapsed_s: float
    #: loops whose compensation was not demonstrated, and why (an unstable loop)
    compensation_skipped: dict[str, str] = field(default_factory=dict)


# --------------------------------------------------------------------------- references
def _reference(setup: LoopSetup, fs: float, duration_s: float, seed: int) -> signals.Signal:
    lo, hi = setup.band_hz
    if setup.loop == "position":
        return signals.band_limited_random(
            band_hz=(lo, hi), duration_s=duration_s, fs=fs, seed=seed, rms=setup.size
        )
    if setup.loop == "acceleration":
        return signals.band_limited_random(
            band_hz=(lo, hi), duration_s=duration_s, fs=fs, seed=seed, peak=setup.size
        )
    return signals.swept_sine(
        setup.size,
        f0_hz=lo,
        f1_hz=hi,
        duration_s=duration_s,
        fs=fs,
        method="linear",
        offset=setup.offset,
    )


# --------------------------------------------------------------------------- one loop
def _validation_band(setup: LoopSetup, fs: float) -> tuple[float, float]:
    lo, hi = setup.band_hz
    return (max(lo, 0.5), min(hi, 0.45 * fs))


def _run_loop(
    setup: LoopSetup, params: RigParams, settings: ProgrammeSettings, seed: int
) -> LoopResult:
    fs = params.timing.control_rate_hz
    settle_s = 1.0 if setup.offset else 0.0
    ref = _reference(setup, fs, settings.duration_s, seed)
    values = ref.values
    if settle_s:
        # Hold the static part first; the record that counts starts once the loop settled.
        values = np.concatenate([np.full(int(round(settle_s * fs)), values[0]), values])
    sim = simulate(setup.loop, values, params=params, seed=seed)
    skip = int(round(settle_s * fs))
    u_raw = sim.reference[skip:]
    y_raw = sim.output[skip:]
    rec = loop_record(
        u_raw, y_raw, fs=fs, band_hz=_validation_band(setup, fs), holdout=settings.holdout
    )
    lam, p0 = settings.forgetting, settings.p0
    paper = identify_and_check(rec, setup.orders, forgetting=lam, p0=p0)
    theta_t, theta_history = convergence(rec, paper.model, forgetting=lam, p0=p0)
    selection = select_order(
        rec.prepared.u,
        rec.prepared.y,
        na=settings.order_grid,
        nb=sorted({k - 1 for k in settings.order_grid}),
        nc=settings.noise_orders,
        delay=setup.orders[3],
        dt=1.0 / fs,
        criterion="aic",
        method="rels",
        init="zero",  # the paper's start, as the refit of the pick uses
    )
    best = selection.best
    recommended = identify_and_check(
        rec, (best.na, best.nb, best.nc, best.delay), forgetting=lam, p0=p0
    )
    passing = None
    if not paper.passes:
        num, den = known_factors(setup.loop, params)
        known = (num, den) if num.size > 1 or den.size > 1 else None
        passing = simplest_passing(
            rec, setup.orders, max_order=settings.max_search_order, forgetting=lam, p0=p0,
            known=known,
        )
    return LoopResult(
        setup=setup,
        sim=_trim(sim, skip),
        record=rec,
        paper=paper,
        selection=selection,
        recommended=recommended,
        passing=passing,
        theta_t=theta_t,
        theta_history=theta_history,
    )


def _trim(sim: SimulationResult, skip: int) -> SimulationResult:
    if skip == 0:
        return sim
    return replace(
        sim,
        t=sim.t[skip:] - sim.t[skip],
        reference=sim.reference[skip:],
        output=sim.output[skip:],
        signals={k: v[skip:] for k, v in sim.signals.items()},
    )


def run_programme(
    params: RigParams | None = None,
    settings: ProgrammeSettings | None = None,
    *,
    progress: Progress | None = None,
    executor: Executor | None = None,
) -> ProgrammeResult:
    """Run the whole programme and return every number and record the report needs.

    Parameters
    ----------
    params : RigParams, optional
        The rig (default preset when omitted).
    settings : ProgrammeSettings, optional
        Seed, durations, orders and signal sizes.
    progress : callable, optional
        Called with a short text before each stage.
    executor : Executor, optional
        Where the compensation demonstrations run while this process runs the step
        tests and identifications (:func:`ehss.experiments.pool.process_pool`). Each
        part has its own seed, so the result is the same as without it.
    """
    params = preset("default") if params is None else params
    settings = ProgrammeSettings() if settings is None else settings
    say = progress or (lambda _msg: None)
    t0 = time.perf_counter()
    demo_names, skipped = _demonstrable(params, settings)
    demo_calls = {
        name: partial(demonstrate, name, params=params, seed=settings.seed + 10 + k,
                      duration_s=settings.compensation_duration_s)
        for k, name in enumerate(demo_names)
    }
    say("step tests (Fig. 12)")
    steps = step_tests(params, duration_s=settings.step_duration_s, seed=settings.seed)
    pending = {}
    if executor is not None and demo_calls:
        # The step tests have compiled most of the kernels the demonstrations use; the
        # rest are compiled here: with an empty numba cache, the two processes would
        # otherwise both compile them at once, twice the work for the same code.
        warm_up(["simulation", "identification"])  # both strands' kernels, once
        for name, call in demo_calls.items():
            say(f"{name} loop: feed-forward compensation (second process)")
            pending[name] = submit(executor, call)
    loops: dict[str, LoopResult] = {}
    for k, (name, setup) in enumerate(settings.setups.items()):
        say(f"{name} loop: simulate, identify, validate")
        loops[name] = _run_loop(setup, params, settings, settings.seed + 1 + k)
    demos: dict[str, CompensationDemo] = {}
    for name in demo_names:
        try:
            if name in pending:
                say(f"{name} loop: feed-forward compensation, waiting for the second "
                    "process")
                demos[name] = collect(pending[name])
            else:
                say(f"{name} loop: feed-forward compensation")
                demos[name] = demo_calls[name]()
        except (ParameterError, DataError) as exc:
            # the compensation's own safety checks refused (an uninvertible model, a
            # drive far beyond the reference): the report says so instead of a drive
            skipped[name] = f"the compensation refused it: {exc}"
    return ProgrammeResult(
        params=params,
        settings=settings,
        steps=steps,
        loops=loops,
        compensation=demos,
        elapsed_s=time.perf_counter() - t0,
        compensation_skipped=skipped,
    )


def _demonstrable(params: RigParams, settings: ProgrammeSettings
                  ) -> tuple[tuple[str, ...], dict[str, str]]:
    """The loops whose compensation is demonstrated, and the others with the reason.

    A loop its gains leave unstable on this rig (linearised, sampled) runs into a limit
    cycle: a model of that record is no closed loop to invert, so it is not demonstrated.
    """
    if not settings.compensation:
        return (), {}
    names: list[str] = []
    skipped: dict[str, str] = {}
    for name in ("position", "acceleration"):
        radius = closed_loop_radius(params, name)
        if radius < 1.0:
            names.append(name)
        else:
            skipped[name] = (f"the {name} loop is unstable with these gains on this rig "
                             f"(linearised closed-loop pole radius {radius:.4f}); "
                             "`ehss params --tune` designs gains for it")
    return tuple(names), skipped
