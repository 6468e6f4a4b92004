"""Closed-loop simulation of one actuator channel with its digital controller.

:func:`simulate` validates the inputs, packs the parameters into the kernel's typed
settings (:class:`~ehss.plant.kernels.PlantSettings`, the controllers'
:class:`~ehss.control.kernels.PidSettings` and :class:`~ehss.control.kernels.TvcSettings`,
the sensors' and the timing), draws the sensor noise and runs the whole loop (plant,
sensors, controller, delay) in one numba kernel
(:func:`ehss.simulation._kernels.closed_loop`). The result is a :class:`SimulationResult`.

Its ``final_state`` (a :class:`SimulationState`: plant, controller, delay line, sensor
noise generator) continues the test: ``simulate(loop, r[n1:], initial_state=
result.final_state)`` after ``result = simulate(loop, r[:n1], seed=s)`` gives the same
samples, bit for bit, as ``simulate(loop, r, seed=s)``; the parameters may change between
the two calls (a payload added while the rig runs) without restarting the controller.
"""

from __future__ import annotations

import dataclasses
import math
import secrets
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from ehss._checks import as_signal, check_int, check_real
from ehss.control.discrete import pid_coefficients, tvc_coefficients
from ehss.control.kernels import PidSettings, TvcSettings
from ehss.errors import ParameterError
from ehss.params import RigParams, preset
from ehss.plant.kernels import PlantState
from ehss.plant.model import (
    apply_initial_state,
    plant_settings,
    rest_state,
    static_force_state,
)
from ehss.simulation import _kernels as SK

__all__ = [
    "LOOPS",
    "LIMIT_FLAGS",
    "SimulationResult",
    "SimulationState",
    "simulate",
    "with_control_rate",
]

#: Closed loops that :func:`simulate` can run.
LOOPS = ("position", "acceleration", "force")

#: Measured controlled variable and its unit, per loop.
_OUTPUT = {
    "position": ("lvdt_m", "m"),
    "acceleration": ("accel_m_s2", "m/s²"),
    "force": ("force_cell_n", "N"),
}

#: The 0/1 limit flags among the signals, and when each is set.
LIMIT_FLAGS = {
    "drive_saturated": "the drive is clipped at the controller's output limit",
    "spool_saturated": "the spool is at ±1",
    "stroke_end": "the piston is beyond ±stroke (on the end stops)",
    "pressure_limit": "a chamber pressure is at 0 or Ps",
}

_SIGNAL_UNITS = {
    "drive_v": "V",
    "valve_command_v": "V",
    "spool": "-",
    "p1_pa": "Pa",
    "p2_pa": "Pa",
    "load_pressure_pa": "Pa",
    "displacement_m": "m",
    "velocity_m_s": "m/s",
    "acceleration_m_s2": "m/s²",
    "force_n": "N",
    "piston_displacement_m": "m",
    "lvdt_m": "m",
    "accel_m_s2": "m/s²",
    "force_cell_n": "N",
    "generated_acceleration_m_s2": "m/s²",
    **dict.fromkeys(LIMIT_FLAGS, "-"),
}


@dataclass(frozen=True, kw_only=True)
class SimulationState:
    """Everything a simulated test needs to continue where it stopped.

    Attributes
    ----------
    loop : str
        Loop it belongs to.
    plant : PlantState
        Plant state at the next control instant.
    memory : ndarray, shape (9 + delay_samples + 1,)
        Periods simulated so far, the controllers' memory and the delay line (the
        layout of :mod:`ehss.simulation._kernels`; read-only).
    rng_state : dict
        State of the sensor noise generator (``numpy.random.PCG64``) after the last draw.
    seed : int
        Seed the test started with.
    fs : float
        Control rate, Hz.
    """

    loop: str
    plant: PlantState
    memory: np.ndarray = dataclasses.field(repr=False)
    rng_state: dict[str, Any] = dataclasses.field(repr=False)
    seed: int
    fs: float

    @property
    def n_samples(self) -> int:
        """Control periods simulated so far."""
        return int(self.memory[SK.MEM_K])

    @property
    def delay_samples(self) -> int:
        """Length of the delay line the state was made with, minus one."""
        return self.memory.size - SK.MEM_BUF - 1


@dataclass(frozen=True, kw_only=True)
class SimulationResult:
    """Record of one simulated test, sampled at the control rate.

    Attributes
    ----------
    t : ndarray, shape (n,)
        Time of each control instant, s (t[0] = 0).
    reference : ndarray, shape (n,)
        Reference in SI units of the loop (m, m/s², N; V or spool for open-loop runs).
    output : ndarray, shape (n,)
        Measured controlled variable (LVDT, accelerometer or load cell, with noise and
        quantisation), sampled at the same instants as ``reference``.
    signals : dict of str to ndarray
        True plant signals (``displacement_m``, ``velocity_m_s``, ``acceleration_m_s2``
        of the table; ``piston_displacement_m``; ``p1_pa``, ``p2_pa``,
        ``load_pressure_pa``; ``force_n`` = Ap·PL − friction; ``spool``), the measured
        ``lvdt_m``, ``accel_m_s2``, ``force_cell_n``, the controller output ``drive_v``
        and the drive reaching the valve after the delay ``valve_command_v``, and 0/1
        flags ``drive_saturated``, ``spool_saturated``, ``stroke_end``,
        ``pressure_limit``. The acceleration loop adds ``generated_acceleration_m_s2``
        (a_d of the generator, eq (10)).
    units : dict of str to str
        Unit of every column of :meth:`to_columns`.
    loop : str
        ``"position"``, ``"acceleration"``, ``"force"`` or ``"open"``.
    fs : float
        Control (sample) rate, Hz.
    seed : int
        Seed of the sensor noise (drawn and recorded when none was given).
    params : RigParams
        Parameters used, with ``timing.control_rate_hz`` equal to ``fs``.
    final_state : SimulationState or None
        State at the end of the record, to continue the test (closed loops).
    """

    t: np.ndarray
    reference: np.ndarray
    output: np.ndarray
    signals: dict[str, np.ndarray]
    units: dict[str, str]
    loop: str
    fs: float
    seed: int
    params: RigParams
    final_state: SimulationState | None = None

    def to_columns(self) -> dict[str, np.ndarray]:
        """Ordered columns ``t, reference, output`` then every signal."""
        cols = {"t": self.t, "reference": self.reference, "output": self.output}
        cols.update(self.signals)
        return cols

    @property
    def limit_fractions(self) -> dict[str, float]:
        """Fraction of the samples each limit flag is set in, by flag
        (:data:`LIMIT_FLAGS` says what each counts)."""
        return {name: float(np.mean(self.signals[name])) if self.t.size else 0.0
                for name in LIMIT_FLAGS}

    @property
    def limits_hit(self) -> dict[str, float]:
        """The limit fractions that are non-zero, by flag."""
        return {k: v for k, v in self.limit_fractions.items() if v > 0.0}


# ----------------------------------------------------------------------------- helpers
def _reference_values(reference: Any, fs: float | None) -> tuple[np.ndarray, float | None]:
    ref_fs = None
    if hasattr(reference, "values") and hasattr(reference, "fs"):
        ref_fs = float(reference.fs)
        reference = reference.values
        if fs is not None and not math.isclose(float(fs), ref_fs, rel_tol=1e-12):
            raise ParameterError(f"fs={fs!r} differs from the reference signal's fs={ref_fs!r}")
    return as_signal(reference, "reference"), (fs if fs is not None else ref_fs)


def with_control_rate(params: RigParams, fs: float | None) -> RigParams:
    """``params`` with the control (sample) rate ``fs``, checked before any work.

    Raises
    ------
    ParameterError
        If ``fs`` is not a positive number that divides the internal (integration) rate
        an integer number of times.
    """
    if fs is None:
        return params
    try:
        fs = float(fs)
    except (TypeError, ValueError):
        raise ParameterError(f"fs={fs!r} must be a number") from None
    timing = params.timing
    if not math.isfinite(fs) or fs <= 0:
        raise ParameterError(f"fs={fs!r} must be a positive number")
    ratio = timing.internal_rate_hz / fs
    if ratio < 1 or abs(ratio - round(ratio)) > 1e-9:
        raise ParameterError(
            f"fs={fs!r} Hz must divide the internal rate timing.internal_rate_hz="
            f"{timing.internal_rate_hz!r} Hz an integer number of times"
        )
    if fs == timing.control_rate_hz:
        return params
    return dataclasses.replace(params, timing=dataclasses.replace(timing, control_rate_hz=fs))


#: Settings of a controller that the loop does not run (the kernel never reads them).
_NOT_RUN_PID = PidSettings._make(math.nan for _ in PidSettings._fields)
_NOT_RUN_TVC = TvcSettings._make(math.nan for _ in TvcSettings._fields)


def _sensor_settings(params: RigParams) -> SK.SensorSettings:
    s, v = params.sensors, params.valve
    lvdt_lsb = accel_lsb = force_lsb = dac_lsb = 0.0  # 0: no quantisation
    if s.quantize:
        # LSB = 2·range / 2^bits over ±10 V
        lvdt_lsb = 2.0 * s.lvdt_range_m / 2.0**s.adc_bits
        accel_lsb = 2.0 * s.accel_range_m_s2 / 2.0**s.adc_bits
        force_lsb = 2.0 * s.force_range_n / 2.0**s.adc_bits
        dac_lsb = 20.0 / 2.0**s.dac_bits
    settings = SK.SensorSettings(
        lvdt_range_m=s.lvdt_range_m,
        lvdt_lsb_m=lvdt_lsb,
        accel_range_m_s2=s.accel_range_m_s2,
        accel_lsb_m_s2=accel_lsb,
        force_range_n=s.force_range_n,
        force_lsb_n=force_lsb,
        dac_lsb_v=dac_lsb,
        command_full_scale_v=v.command_full_scale_v,
        null_bias=v.null_bias,
    )
    # the kernel is compiled for float64 fields, whatever type a value was given in
    return SK.SensorSettings._make(float(x) for x in settings)


def _new_seed(seed: int | None) -> int:
    if seed is None:
        # 128 bits of OS entropy, as np.random.SeedSequence() draws them
        return secrets.randbits(128)
    return check_int(seed, "seed", lo=0)


def _check_initial_state(initial_state: Any) -> Mapping[str, float] | None:
    """``initial_state`` as a mapping of state names to finite floats (or None).

    Raises
    ------
    TypeError
        If it is not a mapping, a name is not a string or a value is not a real number.
    ParameterError
        For a non-finite value (unknown names: :func:`apply_initial_state`).
    """
    if initial_state is None:
        return None
    if not isinstance(initial_state, Mapping):
        raise TypeError(
            f"initial_state must be a mapping of state names to values (e.g. "
            f"{{'displacement_m': 0.01}}), got {type(initial_state).__name__}"
        )
    checked: dict[str, float] = {}
    for name, value in initial_state.items():
        if not isinstance(name, str):
            raise TypeError(f"initial_state key {name!r} must be a state name (str)")
        checked[name] = check_real(value, f"initial_state[{name!r}]")
    return checked


def _check_resume(state: SimulationState, loop: str, params: RigParams,
                  seed: int | None) -> None:
    """A full state continues only the loop and timing it was made with."""
    if state.loop != loop:
        raise ParameterError(f"initial_state is of a {state.loop!r} loop, not {loop!r}")
    if seed is not None:
        raise ParameterError("seed and a SimulationState exclude each other: the state "
                             "carries the noise generator of the test it continues")
    if state.fs != params.timing.control_rate_hz:
        raise ParameterError(f"initial_state was made at fs={state.fs:g} Hz, the run is at "
                             f"{params.timing.control_rate_hz:g} Hz")
    if state.delay_samples != params.timing.delay_samples:
        raise ParameterError(f"initial_state has a delay line of {state.delay_samples} "
                             f"samples, params.timing.delay_samples="
                             f"{params.timing.delay_samples}")


def _fresh_memory(delay_samples: int, drive0_v: float) -> np.ndarray:
    """Memory of a test that starts: no period run, the PID's integral and the delay
    line holding ``drive0_v``, the TVC at rest."""
    mem = np.zeros(SK.MEM_BUF + delay_samples + 1)
    mem[SK.MEM_PID] = drive0_v
    mem[SK.MEM_BUF:] = drive0_v
    return mem


def _draw_noise(rng: np.random.Generator, n: int, params: RigParams) -> SK.SensorNoise:
    """Sensor noise of ``n`` periods, drawn period by period (LVDT, accelerometer, load
    cell), so that blocks drawn one after another equal one draw."""
    s = params.sensors
    sigma = np.array([s.lvdt_noise_m, s.accel_noise_m_s2, s.force_noise_n])
    noise = np.ascontiguousarray((rng.standard_normal((n, 3)) * sigma).T)
    return SK.SensorNoise._make(noise)


def _kernel_inputs(
    loop: str,
    values: np.ndarray,
    params: RigParams,
    *,
    seed: int,
    initial_state: Mapping[str, float] | SimulationState | None,
    spool_direct: bool,
    stiffness_n_m: float,
) -> tuple[PlantState, SK.SensorNoise, SK.LoopSettings, np.ndarray, np.random.Generator]:
    """Initial plant state, sensor noise, settings, memory and noise generator of the
    loop kernel for one run."""
    timing = params.timing
    h = 1.0 / timing.internal_rate_hz
    plant = plant_settings(
        params, stiffness_n_m=stiffness_n_m, internal_dt_s=h, spool_direct=spool_direct
    )
    dt = timing.dt_s
    # one compiled kernel serves every loop: the controller a loop does not run is NaN
    pid = _NOT_RUN_PID
    tvc = _NOT_RUN_TVC
    if loop in ("position", "force"):
        pid = pid_coefficients(params.force if loop == "force" else params.position, dt)
    elif loop == "acceleration":
        tvc = tvc_coefficients(params.acceleration, dt)
    drive0 = 0.0
    if isinstance(initial_state, SimulationState):
        x0 = initial_state.plant
        mem = np.array(initial_state.memory, dtype=float)
        rng = np.random.default_rng()
        rng.bit_generator.state = initial_state.rng_state
    else:
        x0 = rest_state(params)
        if loop == "force" and initial_state is None and values[0] != 0.0 \
                and stiffness_n_m > 0.0:
            # start in equilibrium on the first reference value (bumpless: the integrator
            # holds the drive that keeps the valve open against the leakage)
            x0, drive0 = static_force_state(params, float(values[0]), plant)
        elif loop == "open" and spool_direct:
            x0 = x0._replace(spool=float(values[0]))
        x0 = apply_initial_state(x0, initial_state)
        mem = _fresh_memory(int(timing.delay_samples), drive0)
        rng = np.random.default_rng(seed)
    noise = _draw_noise(rng, values.size, params)

    settings = SK.LoopSettings(
        loop=SK.LOOP_IDS[loop],
        plant=plant,
        sensors=_sensor_settings(params),
        pid=pid,
        tvc=tvc,
        substeps=int(timing.substeps),
        step_s=float(h),
        delay_samples=int(timing.delay_samples),
        drive0_v=float(drive0),
    )
    return x0, noise, settings, mem, rng


def _run(
    loop: str,
    reference: Any,
    *,
    params: RigParams | None,
    fs: float | None,
    seed: int | None,
    initial_state: Mapping[str, float] | SimulationState | None,
    spool_direct: bool = False,
    stiffness_n_m: float | None = None,
) -> SimulationResult:
    """Shared machinery of :func:`simulate` and :func:`simulate_open_loop`."""
    if params is None:
        params = preset("default")
    if not isinstance(params, RigParams):
        raise TypeError(f"params must be a RigParams, got {type(params).__name__}")
    values, fs = _reference_values(reference, fs)
    params = with_control_rate(params, fs)
    if isinstance(initial_state, SimulationState):
        _check_resume(initial_state, loop, params, seed)
        seed = initial_state.seed
    else:
        initial_state = _check_initial_state(initial_state)
        seed = _new_seed(seed)
    timing = params.timing
    fs = timing.control_rate_hz
    n = values.size

    if stiffness_n_m is None:
        stiffness_n_m = (
            params.load.specimen_stiffness_n_m if loop == "force" else params.load.stiffness_n_m
        )
    x0, noise, settings, mem, rng = _kernel_inputs(
        loop, values, params, seed=seed, initial_state=initial_state,
        spool_direct=spool_direct, stiffness_n_m=stiffness_n_m,
    )
    record = SK.LoopRecord._make(np.empty((len(SK.LoopRecord._fields), n)))
    if not values.flags.writeable:
        # numba types a read-only array apart from a writable one and would compile the
        # loop kernel a second time (seconds) for it; a copy costs microseconds
        values = values.copy()
    x_end = SK.closed_loop(values, noise, x0, settings, record, mem)
    mem.setflags(write=False)
    final_state = SimulationState(loop=loop, plant=PlantState._make(float(v) for v in x_end),
                                  memory=mem, rng_state=dict(rng.bit_generator.state), seed=seed,
                                  fs=float(fs))
    rows = record._asdict()
    aux = rows.pop("aux")
    signals: dict[str, np.ndarray] = {}
    for name, row in rows.items():
        signals[name] = row
        if name == "p2_pa":
            signals["load_pressure_pa"] = rows["p1_pa"] - rows["p2_pa"]
    if loop == "acceleration":
        signals["generated_acceleration_m_s2"] = aux
    if loop == "open":
        out_name, out_unit = ("force_cell_n", "N") if stiffness_n_m > 0 else ("lvdt_m", "m")
        ref_unit = "-" if spool_direct else "V"
    else:
        out_name, out_unit = _OUTPUT[loop]
        ref_unit = out_unit
    t = np.arange(n) / fs
    units = {"t": "s", "reference": ref_unit, "output": out_unit}
    units.update({name: _SIGNAL_UNITS[name] for name in signals})
    if spool_direct:
        units["valve_command_v"] = "-"
        units["drive_v"] = "-"
    output = signals[out_name].copy()
    reference_out = values.copy()
    for arr in (t, output, reference_out, *signals.values()):
        arr.setflags(write=False)
    return SimulationResult(
        t=t,
        reference=reference_out,
        output=output,
        signals=signals,
        units=units,
        loop=loop,
        fs=float(fs),
        seed=seed,
        params=params,
        final_state=final_state,
    )


def simulate(
    loop: str,
    reference: Any,
    *,
    params: RigParams | None = None,
    fs: float | None = None,
    seed: int | None = None,
    initial_state: Mapping[str, float] | SimulationState | None = None,
) -> SimulationResult:
    """Simulate a closed-loop test of one actuator channel.

    The nonlinear plant (servo valve eq (1), orifice flows of the valve rating, chamber
    continuity eq (5) per chamber, load eq (6), friction, clearance, stroke ends, pressure
    limits) is integrated with fixed-step RK4 at ``timing.internal_rate_hz``; the sensors
    are sampled at the control rate with noise and ADC quantisation; the controller of
    the loop (position PID, TVC of eqs (10)–(12) and Fig. 6, or force PID of eq (15))
    computes the drive, which is clipped, DAC-quantised and applied after
    ``timing.delay_samples`` periods through a zero-order hold.

    Parameters
    ----------
    loop : {"position", "acceleration", "force"}
        Which loop is closed.
    reference : ndarray, shape (n,), or Signal
        Reference per control period in SI units of the loop: m, m/s² or N. An object
        with ``.values`` and ``.fs`` (e.g. :class:`ehss.signals.Signal`) gives its rate.
    params : RigParams, optional
        Parameter set (default preset ``"default"``).
    fs : float, optional
        Control rate, Hz; replaces ``params.timing.control_rate_hz`` and must divide
        ``timing.internal_rate_hz``.
    seed : int, optional
        Seed of the sensor noise; drawn at random (and recorded in the result) if None.
    initial_state : mapping or SimulationState, optional
        Plant state overrides by name (:data:`ehss.plant.model.STATE_NAMES`). Without it
        the plant starts at rest mid-stroke with both chambers at (Ps + Pr)/2; the force
        loop starts in equilibrium holding the first reference value against the
        specimen stiffness (the paper's force sweep runs about a 25 kgf offset).
        A :class:`SimulationState` (a previous result's ``final_state``) continues that
        test instead: plant, controller, delay line and noise generator, bit for bit
        (``seed`` must then be None; ``params`` may differ, with the same timing).

    Returns
    -------
    SimulationResult
        With ``final_state`` to continue the test.

    Raises
    ------
    ParameterError
        Unknown loop, ``fs`` not dividing the internal rate, bad seed, unknown or
        non-finite initial state, a :class:`SimulationState` of another loop, rate or
        delay, or with a seed.
    TypeError
        ``initial_state`` not a mapping of state names to real numbers.
    DataError
        Reference not 1-D, empty or not finite (the first bad index is named).

    Notes
    -----
    With noise 0, ``quantize=False``, ``saturate=False``, ``delay_samples=0``, no AC
    coupling, friction or clearance, the plant reduces at small amplitude to the linear
    model of eqs (7) and (8) (tested in ``tests/plant``).

    Examples
    --------
    >>> import numpy as np
    >>> from ehss.simulation import simulate
    >>> r = simulate("position", np.full(500, 0.005), seed=1)
    >>> bool(abs(r.output[-1] - 0.005) < 2e-4)
    True
    """
    if loop not in LOOPS:
        raise ParameterError(f"unknown loop {loop!r}; choose one of {list(LOOPS)}")
    return _run(loop, reference, params=params, fs=fs, seed=seed, initial_state=initial_state)
