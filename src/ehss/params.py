"""Parameter sets of the electro-hydraulic servo system (EHSS).

One actuator channel of the shaking table / loading rig is described by frozen,
keyword-only dataclasses in SI units: servo valve, actuator and fluid, load, sensors,
the three controllers and the timing of the digital controller. :class:`RigParams`
holds them all and exposes the derived quantities of the paper's linear model
(eqs 3–8) as properties.

Two presets exist:

``"default"``
    The consistent set of the paper's clean reading (PAPER.md §5): 250 kg carried by one
    actuator (1000 kg table + 1000 kg payload shared by 8 actuators), which with the
    printed Vt, βe and Ap gives ωh ≈ 32 Hz; a total flow-pressure coefficient
    Kce = 1.44e-11 m³/(s·Pa) that gives ζh ≈ 0.35; the Moog G761-3004 valve modelled by its
    rating (38 L/min at 7 MPa valve drop) at Ps = 21 MPa; 1 kHz control rate.
``"paper"``
    Table 1 and Table 3 exactly as printed (mt = 5000 kg, Kc = 2e-12 m³/(s·Pa),
    Kq = 0.00145 (m³/s)/V, the Table 3 gains). It is kept for comparison; taken
    literally it gives ωh ≈ 7.2 Hz and ζh ≈ 0.12, not the printed 32 Hz / 0.35.

Parameter sets round-trip through TOML (:func:`load_params`, :func:`save_params`);
variants are made with :func:`dataclasses.replace`.

Every field is checked on construction: booleans must be ``True``/``False`` (a TOML
``"no"`` is refused, not read as true), integers integers, and real numbers finite and
inside the physically sensible range of :data:`RANGES`, which also bounds the work a
simulation implies (integration at most at 1 MHz and :data:`MAX_SUBSTEPS` steps per
control period). Wrong Python types raise TypeError and bad values ParameterError from the
API; from a file, both become a ParameterError naming the file, ``section.key`` and what
is accepted.
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

from ehss._checks import check_bool, check_int, check_real
from ehss._files import parse_document, read_small_file
from ehss.errors import ParameterError

__all__ = [
    "ValveParams",
    "ActuatorParams",
    "LoadParams",
    "SensorParams",
    "PositionPidParams",
    "TvcParams",
    "ForcePidParams",
    "TimingParams",
    "RigLimits",
    "RigParams",
    "PRESETS",
    "preset",
    "load_params",
    "save_params",
    "params_to_dict",
    "params_from_dict",
    "describe_params",
    "RANGES",
    "MAX_PARAMS_FILE_BYTES",
    "MAX_SUBSTEPS",
]

GRAVITY_M_S2 = 9.80665
LITRE_PER_MIN_M3_S = 1e-3 / 60.0


# --------------------------------------------------------------------------- checks
# Accepted range of every numeric field: (lo, hi, lo_open, hi_open), in the field's SI unit.
# The ranges are physically sensible for a hydraulic servo channel with generous margins
# (a valve of up to 60 000 L/min, a 10 m² piston, 10 000 t of moving mass) and bound the
# work a simulation implies: the plant is integrated at timing.internal_rate_hz, so that
# rate is capped at 1 MHz and at 1000 integration steps per control period.
_OPEN = (True, False)  # (lo, hi]
_CLOSED = (False, False)  # [lo, hi]
RANGES: dict[str, dict[str, tuple[float, float, bool, bool]]] = {
    "ValveParams": {
        "rated_flow_m3_s": (0.0, 1.0, *_OPEN),
        "rated_pressure_drop_pa": (1e4, 1e9, *_CLOSED),
        "natural_freq_hz": (0.1, 1e6, *_CLOSED),
        "damping": (0.0, 100.0, *_OPEN),
        "null_leakage_m3_s_pa": (0.0, 1e-6, *_CLOSED),
        "deadband": (0.0, 0.5, False, True),
        "null_bias": (-0.5, 0.5, True, True),
        "command_full_scale_v": (0.0, 1e3, *_OPEN),
    },
    "ActuatorParams": {
        "piston_area_m2": (0.0, 10.0, *_OPEN),
        "total_volume_m3": (0.0, 100.0, *_OPEN),
        "bulk_modulus_pa": (1e6, 1e11, *_CLOSED),
        "supply_pressure_pa": (1e4, 1e9, *_CLOSED),
        "return_pressure_pa": (0.0, 1e9, *_CLOSED),
        "internal_leakage_m3_s_pa": (0.0, 1e-6, *_CLOSED),
        "external_leakage_m3_s_pa": (0.0, 1e-6, *_CLOSED),
        "oil_density_kg_m3": (100.0, 1e4, *_CLOSED),
        "stroke_m": (0.0, 100.0, *_OPEN),
    },
    "LoadParams": {
        "mass_kg": (1e-3, 1e7, *_CLOSED),
        "damping_n_s_m": (0.0, 1e12, *_CLOSED),
        "stiffness_n_m": (0.0, 1e12, *_CLOSED),
        "specimen_stiffness_n_m": (0.0, 1e12, *_CLOSED),
        "coulomb_friction_n": (0.0, 1e9, *_CLOSED),
        "stribeck_friction_n": (0.0, 1e9, *_CLOSED),
        "stribeck_velocity_m_s": (1e-9, 100.0, *_CLOSED),
        "clearance_m": (0.0, 1.0, *_CLOSED),
    },
    "SensorParams": {
        "lvdt_range_m": (0.0, 100.0, *_OPEN),
        "accel_range_m_s2": (0.0, 1e6, *_OPEN),
        "force_range_n": (0.0, 1e9, *_OPEN),
        "lvdt_noise_m": (0.0, 100.0, *_CLOSED),
        "accel_noise_m_s2": (0.0, 1e6, *_CLOSED),
        "force_noise_n": (0.0, 1e9, *_CLOSED),
        "accel_highpass_hz": (0.0, 1e4, *_CLOSED),
        "adc_bits": (2, 32, *_CLOSED),
        "dac_bits": (2, 32, *_CLOSED),
    },
    "PositionPidParams": {
        "kp_v_per_m": (0.0, 1e12, *_OPEN),
        "ki_v_per_m_per_s": (0.0, 1e12, *_CLOSED),
        "kd_v_s_per_m": (0.0, 1e12, *_CLOSED),
        "derivative_filter_hz": (0.0, 1e6, *_OPEN),
        "output_limit_v": (0.0, 1e3, *_OPEN),
    },
    "TvcParams": {
        "kg": (0.0, 1e6, *_OPEN),
        "generator_omega_rad_s": (0.0, 1e6, *_OPEN),
        "generator_damping": (0.0, 100.0, *_OPEN),
        "kdf_v_per_m": (-1e12, 1e12, *_CLOSED),
        "kvf_v_per_m_s": (-1e12, 1e12, *_CLOSED),
        "kaf_v_per_m_s2": (-1e12, 1e12, *_CLOSED),
        "kdr": (-1e12, 1e12, *_CLOSED),
        "kvr_s": (-1e12, 1e12, *_CLOSED),
        "kar_s2": (-1e12, 1e12, *_CLOSED),
        "velocity_crossover_hz": (0.0, 1e6, *_OPEN),
        "output_limit_v": (0.0, 1e3, *_OPEN),
    },
    "ForcePidParams": {
        "kp_v_per_n": (0.0, 1e12, *_OPEN),
        "ki_v_per_n_per_s": (0.0, 1e12, *_CLOSED),
        "kd_v_s_per_n": (0.0, 1e12, *_CLOSED),
        "derivative_filter_hz": (0.0, 1e6, *_OPEN),
        "output_limit_v": (0.0, 1e3, *_OPEN),
    },
    "TimingParams": {
        "control_rate_hz": (1.0, 1e5, *_CLOSED),
        "internal_rate_hz": (1.0, 1e6, *_CLOSED),
        "delay_samples": (0, 100, *_CLOSED),
    },
    "RigLimits": {
        "max_velocity_m_s": (0.0, 1e3, *_OPEN),
        "max_acceleration_m_s2": (0.0, 1e5, *_OPEN),
        "max_force_n": (0.0, 1e10, *_OPEN),
    },
}
#: Most plant integration steps per control period (timing.internal_rate_hz / control_rate_hz).
MAX_SUBSTEPS = 1000


def _validate_fields(obj: Any) -> None:
    """Check every field of a parameter section against its type and :data:`RANGES`.

    Booleans must be ``True``/``False``, integers integers, and real numbers finite and in
    range. Integers given for real fields are stored as floats. Wrong Python types raise
    TypeError, bad values ParameterError (both name ``Section.field`` and the range).
    """
    cls = type(obj).__name__
    ranges = RANGES[cls]
    for f in fields(obj):
        value = getattr(obj, f.name)
        name = f"{cls}.{f.name}"
        default: object = f.default
        kind = type(default)
        if kind is bool:
            check_bool(value, name)
        elif kind is int:
            lo, hi, _, _ = ranges[f.name]
            check_int(value, name, lo=int(lo), hi=int(hi))
        else:
            lo, hi, lo_open, hi_open = ranges[f.name]
            x = check_real(value, name, lo=lo, hi=hi, lo_open=lo_open, hi_open=hi_open,
                           unit=_unit(f.name).replace("-", ""))
            object.__setattr__(obj, f.name, x)


def _unit(name: str) -> str:
    """Unit of a field, read from its name's suffix (used for printing)."""
    suffixes = {
        "_m3_s_pa": "m³/(s·Pa)",
        "_m3_s_v": "(m³/s)/V",
        "_m3_s": "m³/s",
        "_m3": "m³",
        "_m2": "m²",
        "_kg_m3": "kg/m³",
        "_kg": "kg",
        "_pa": "Pa",
        "_n_s_m": "N·s/m",
        "_n_m": "N/m",
        "_n": "N",
        "_m_s2": "m/s²",
        "_m_s": "m/s",
        "_m": "m",
        "_rad_s": "rad/s",
        "_hz": "Hz",
        "_s": "s",
        "_v_per_m": "V/m",
        "_v_per_m_s": "V/(m/s)",
        "_v_per_m_s2": "V/(m/s²)",
        "_v_per_n": "V/N",
        "_v_per_m_per_s": "V/(m·s)",
        "_v_per_n_per_s": "V/(N·s)",
        "_v_s_per_n": "V·s/N",
        "_v_s_per_m": "V·s/m",
        "_v": "V",
        "_bits": "bit",
    }
    for suffix in sorted(suffixes, key=len, reverse=True):
        if name.endswith(suffix):
            return suffixes[suffix]
    return "-"


class _Section:
    """A section of :class:`RigParams`: its fields are checked against :data:`RANGES`
    when it is made (:func:`_validate_fields`)."""

    def __post_init__(self) -> None:
        _validate_fields(self)


# --------------------------------------------------------------------------- plant
@dataclass(frozen=True, kw_only=True)
class ValveParams(_Section):
    """Two-stage servo valve (Moog G761-3004), eqs (1)–(4).

    The spool position is normalised, u ∈ [−1, 1]; the command is a voltage with
    ``command_full_scale_v`` giving full spool. Flow follows the valve's rating
    (PAPER.md §5) instead of the paper's inconsistent Kq:

    .. math:: Q = Q_r\\,u\\,\\sqrt{(P_s - \\operatorname{sgn}(u) P_L)/\\Delta p_r}

    Attributes
    ----------
    rated_flow_m3_s : float
        Qr, flow at full spool and the rated valve drop (38 L/min).
    rated_pressure_drop_pa : float
        Δp_r, total valve drop at which Qr is rated (7 MPa, both lands).
    natural_freq_hz : float
        ωv/2π of the second-order spool dynamics, eq (1).
    damping : float
        ζv of eq (1).
    null_leakage_m3_s_pa : float
        Kc at null, eq (4): laminar leakage across each metering land. A critically
        lapped orifice has Kc = 0 at null; real spools leak, and this is the
        operating-point Kc of the linear model.
    deadband : float
        Overlap as a fraction of full spool stroke (0 = critically lapped).
    null_bias : float
        Spool offset at zero command, fraction of full stroke.
    command_full_scale_v : float
        Command voltage giving u = 1 (Kv = 1/command_full_scale_v in eq (1)).
    saturate : bool
        Limit the spool to [−1, 1].
    """

    rated_flow_m3_s: float = 38.0 * LITRE_PER_MIN_M3_S
    rated_pressure_drop_pa: float = 7.0e6
    natural_freq_hz: float = 120.0
    damping: float = 0.7
    null_leakage_m3_s_pa: float = 1.44e-11
    deadband: float = 0.0
    null_bias: float = 0.0
    command_full_scale_v: float = 10.0
    saturate: bool = True

    @property
    def gain_per_v(self) -> float:
        """Kv of eq (1): normalised spool per volt of command."""
        return 1.0 / self.command_full_scale_v

    @property
    def omega_rad_s(self) -> float:
        """ωv of eq (1), rad/s."""
        return 2.0 * math.pi * self.natural_freq_hz


@dataclass(frozen=True, kw_only=True)
class ActuatorParams(_Section):
    """Double-rod actuator and hydraulic fluid, eqs (2)–(7).

    Attributes
    ----------
    piston_area_m2 : float
        Ap, annulus area: π/4 (0.07² − 0.05²) = 1.885e-3 m² (70 mm bore, 50 mm rod).
    total_volume_m3 : float
        Vt, total compressed volume of both chambers and lines.
    bulk_modulus_pa : float
        βe, effective bulk modulus.
    supply_pressure_pa, return_pressure_pa : float
        Ps (assumed 21 MPa; not printed) and the tank pressure.
    internal_leakage_m3_s_pa, external_leakage_m3_s_pa : float
        Cip and Cep of eq (5); Ctc = Cip + Cep/2.
    oil_density_kg_m3 : float
        ρ of eqs (3)–(4); used when Kq is expressed as Cd·w·√(Δp/ρ).
    stroke_m : float
        Half stroke: the piston may move in [−stroke_m, +stroke_m] (Table 2, ±100 mm).
    """

    piston_area_m2: float = math.pi / 4.0 * (0.07**2 - 0.05**2)
    total_volume_m3: float = 0.96e-3
    bulk_modulus_pa: float = 6.9e8
    supply_pressure_pa: float = 21.0e6
    return_pressure_pa: float = 0.0
    internal_leakage_m3_s_pa: float = 4.6e-17
    external_leakage_m3_s_pa: float = 4.6e-17
    oil_density_kg_m3: float = 870.0
    stroke_m: float = 0.1

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.return_pressure_pa >= self.supply_pressure_pa:
            raise ParameterError(
                f"ActuatorParams.return_pressure_pa={self.return_pressure_pa!r} must be below "
                f"supply_pressure_pa={self.supply_pressure_pa!r}"
            )
        # Each chamber holds Vt/2 at mid-stroke; the piston must not sweep it empty.
        if self.piston_area_m2 * self.stroke_m >= 0.5 * self.total_volume_m3:
            raise ParameterError(
                f"ActuatorParams: piston_area_m2*stroke_m="
                f"{self.piston_area_m2 * self.stroke_m:.3g} m³ must be below half of "
                f"total_volume_m3={self.total_volume_m3!r} (a chamber would empty)"
            )


@dataclass(frozen=True, kw_only=True)
class LoadParams(_Section):
    """Moving mass, damping, stiffness and the optional nonlinear load effects, eq (6).

    Attributes
    ----------
    mass_kg : float
        mt, mass carried by one actuator (table + payload shared by 8 actuators).
    damping_n_s_m : float
        Bp, viscous damping.
    stiffness_n_m : float
        K of eq (6) in position and acceleration tests (0 for the free table).
    specimen_stiffness_n_m : float
        K of eq (6) when the force loop is closed on a clamped specimen / load cell
        (Table 1: 2e7 N/m).
    coulomb_friction_n, stribeck_friction_n, stribeck_velocity_m_s : float
        Friction Fc + (Fs − Fc)… in the Stribeck form
        F = sgn(v)[Fc + Fs exp(−(v/vs)²)]; 0 switches friction off.
    clearance_m : float
        Total joint clearance (backlash) between rod and table; 0 switches it off.
    """

    mass_kg: float = 250.0
    damping_n_s_m: float = 25_000.0
    stiffness_n_m: float = 0.0
    specimen_stiffness_n_m: float = 2.0e7
    coulomb_friction_n: float = 0.0
    stribeck_friction_n: float = 0.0
    stribeck_velocity_m_s: float = 0.005
    clearance_m: float = 0.0


@dataclass(frozen=True, kw_only=True)
class SensorParams(_Section):
    """LVDT, accelerometer, load cell and converters (PAPER.md §7).

    Each sensor maps its full-scale range to ±10 V on a ``adc_bits`` converter; noise is
    white with the given RMS in SI units. A noise of 0 and ``quantize=False`` make the
    sensors ideal.

    Attributes
    ----------
    lvdt_range_m : float
        Displacement at 10 V (±100 mm gives an LSB of about 3 µm at 16 bit).
    accel_range_m_s2 : float
        Acceleration at 10 V (±5 g gives an LSB of about 0.15 mg).
    force_range_n : float
        Force at 10 V (±1.5 t gives an LSB of about 0.45 N).
    lvdt_noise_m, accel_noise_m_s2, force_noise_n : float
        RMS white noise.
    accel_highpass_hz : float
        Corner of the accelerometer's AC coupling (first-order high-pass); 0 = DC coupled.
    adc_bits, dac_bits : int
        Converter resolutions over ±10 V.
    quantize : bool
        Apply ADC and DAC quantisation.
    """

    lvdt_range_m: float = 0.1
    accel_range_m_s2: float = 5.0 * GRAVITY_M_S2
    force_range_n: float = 1500.0 * GRAVITY_M_S2
    lvdt_noise_m: float = 2.0e-6
    accel_noise_m_s2: float = 0.01
    force_noise_n: float = 0.5
    accel_highpass_hz: float = 0.5
    adc_bits: int = 16
    dac_bits: int = 16
    quantize: bool = True

    def __post_init__(self) -> None:
        super().__post_init__()
        for noise, full in (("lvdt_noise_m", "lvdt_range_m"),
                            ("accel_noise_m_s2", "accel_range_m_s2"),
                            ("force_noise_n", "force_range_n")):
            if getattr(self, noise) > getattr(self, full):
                raise ParameterError(
                    f"SensorParams.{noise}={getattr(self, noise)!r} must not exceed "
                    f"{full}={getattr(self, full)!r} (noise larger than the sensor's range)"
                )


# --------------------------------------------------------------------------- control
@dataclass(frozen=True, kw_only=True)
class PositionPidParams(_Section):
    """PID on LVDT displacement, eq (9) (Kd of eq (9) is ``kp_v_per_m``).

    u = kp·e + ki·∫e + kd·D(e), with D a derivative filtered by a first-order low-pass at
    ``derivative_filter_hz``; the integrator stops when the output saturates at
    ``output_limit_v`` (anti-windup by conditional integration).

    The defaults are :func:`ehss.control.tuning.tune_position` of the default rig rounded
    to 4 significant digits: kp for a 6.5 dB gain margin of the sampled loop (valve, ZOH,
    one sample of delay), integral corner at 5 % of the crossover; closed loop −1.5 dB at
    20 Hz.
    """

    kp_v_per_m: float = 978.0
    ki_v_per_m_per_s: float = 2798.0
    kd_v_s_per_m: float = 0.0
    derivative_filter_hz: float = 200.0
    output_limit_v: float = 10.0


@dataclass(frozen=True, kw_only=True)
class TvcParams(_Section):
    """Three-variable controller of the acceleration loop, eqs (10)–(13) and Fig. 6.

    The acceleration reference a_r passes through the acceleration generator
    GAR(s) = Kg / (s² + ωg s + δg) of eq (10), giving the displacement reference r_d and
    its derivatives v_d = s r_d, a_d = s² r_d. The drive is

    .. math:: u = K_{df}\\,(K_{dr} r_d + K_{vr} v_d + K_{ar} a_d - y) - K_{vf} \\hat v - K_{af} a

    with y the LVDT displacement, a the (AC-coupled) accelerometer signal and v̂ the
    velocity blended from both by complementary filters,
    v̂ = (ωc s y + a) / (s + ωc), ωc = 2π ``velocity_crossover_hz``.

    Attributes
    ----------
    kg : float
        Kg of eq (10), acceleration generator gain.
    generator_omega_rad_s, generator_damping : float
        ωn and ζn of eq (10): ωg = 2ζn ωn, δg = ωn².
    kdf_v_per_m, kvf_v_per_m_s, kaf_v_per_m_s2 : float
        Feedback gains on displacement error, synthesised velocity and acceleration.
    kdr, kvr_s, kar_s2 : float
        Feed-forward B(s) = Kdr + Kvr s + Kar s² of eq (12), applied to the generated
        displacement reference before the displacement error (dimensionless, s, s²).
    velocity_crossover_hz : float
        Crossover of the complementary filters that blend the differentiated LVDT
        (below) with the integrated accelerometer (above) into the velocity feedback.
    output_limit_v : float
        Drive saturation.

    The defaults are :func:`ehss.control.tuning.tune_tvc` of the default rig rounded to
    4 significant digits: pole placement of eq (11) with ωnc = 1.05 ωh, ζnc = 0.7 and the
    largest ωd (≈ 2π·11 Hz) that keeps a 6.5 dB gain margin on the sampled loop; eq (12)
    feed-forward Kdr = 1, Kvr = 2ζnc/ωnc, Kar = 1/ωnc²; Kg, ωn, ζn of Table 3.
    """

    kg: float = 1.0
    generator_omega_rad_s: float = 3.14
    generator_damping: float = 0.7
    kdf_v_per_m: float = 1307.0
    kvf_v_per_m_s: float = 8.640
    kaf_v_per_m_s2: float = 0.09450
    kdr: float = 1.0
    kvr_s: float = 0.006596
    kar_s2: float = 2.220e-05
    velocity_crossover_hz: float = 5.0
    output_limit_v: float = 10.0


@dataclass(frozen=True, kw_only=True)
class ForcePidParams(_Section):
    """PID on load-cell force, eqs (14)–(15) (Gcf of eq (15)).

    The defaults are :func:`ehss.control.tuning.tune_force` of the default rig rounded to
    4 significant digits: a PI whose zero cancels the pressure pole ωr of eq (8)
    (ki = kp ωr), kp for a 6.5 dB gain margin of the sampled loop; closed loop −1.4 dB at
    20 Hz.
    """

    kp_v_per_n: float = 3.213e-4
    ki_v_per_n_per_s: float = 8.804e-3
    kd_v_s_per_n: float = 0.0
    derivative_filter_hz: float = 200.0
    output_limit_v: float = 10.0


@dataclass(frozen=True, kw_only=True)
class TimingParams(_Section):
    """Sample rates of the digital controller and of the plant integration.

    The plant is integrated with fixed steps at ``internal_rate_hz``, which must be an
    integer multiple of ``control_rate_hz`` (the xPC target's sample rate; not printed in
    the paper, 1 kHz fits its identified models). ``delay_samples`` control periods pass
    between sampling the sensors and applying the drive (zero-order hold).
    """

    control_rate_hz: float = 1000.0
    internal_rate_hz: float = 10_000.0
    delay_samples: int = 1

    def __post_init__(self) -> None:
        super().__post_init__()
        ratio = self.internal_rate_hz / self.control_rate_hz
        if ratio < 1 or abs(ratio - round(ratio)) > 1e-9:
            raise ParameterError(
                f"TimingParams: internal_rate_hz={self.internal_rate_hz!r} must be an integer "
                f"multiple of control_rate_hz={self.control_rate_hz!r}"
            )
        if round(ratio) > MAX_SUBSTEPS:
            raise ParameterError(
                f"TimingParams: internal_rate_hz={self.internal_rate_hz!r} is "
                f"{round(ratio)} times control_rate_hz={self.control_rate_hz!r}; at most "
                f"{MAX_SUBSTEPS} plant steps per control period are accepted"
            )

    @property
    def substeps(self) -> int:
        """Plant integration steps per control period."""
        return int(round(self.internal_rate_hz / self.control_rate_hz))

    @property
    def dt_s(self) -> float:
        """Control period, s."""
        return 1.0 / self.control_rate_hz


@dataclass(frozen=True, kw_only=True)
class RigLimits(_Section):
    """Performance limits of the rig (Table 2) that a test must respect."""

    max_velocity_m_s: float = 0.2
    max_acceleration_m_s2: float = 1.0 * GRAVITY_M_S2
    max_force_n: float = 1500.0 * GRAVITY_M_S2


@dataclass(frozen=True, kw_only=True)
class RigParams:
    """Everything that defines one simulated actuator channel and its controllers.

    Derived quantities of the linear model are properties; see eqs (3)–(8).

    Examples
    --------
    >>> import ehss
    >>> p = ehss.preset("default")
    >>> round(p.hydraulic_freq_hz, 1), round(p.hydraulic_damping, 2)
    (32.2, 0.35)
    """

    name: str = "default"
    valve: ValveParams = field(default_factory=ValveParams)
    actuator: ActuatorParams = field(default_factory=ActuatorParams)
    load: LoadParams = field(default_factory=LoadParams)
    sensors: SensorParams = field(default_factory=SensorParams)
    position: PositionPidParams = field(default_factory=PositionPidParams)
    acceleration: TvcParams = field(default_factory=TvcParams)
    force: ForcePidParams = field(default_factory=ForcePidParams)
    timing: TimingParams = field(default_factory=TimingParams)
    limits: RigLimits = field(default_factory=RigLimits)

    def __post_init__(self) -> None:
        for f in fields(self):
            if f.name == "name":
                if not isinstance(self.name, str):
                    raise TypeError(f"RigParams.name={self.name!r} must be a string")
                continue
            expected = f.default_factory
            assert isinstance(expected, type), f"RigParams.{f.name} needs a class as factory"
            value = getattr(self, f.name)
            if not isinstance(value, expected):
                raise TypeError(
                    f"RigParams.{f.name} must be a {expected.__name__}, "
                    f"got {type(value).__name__}"
                )

    # ----------------------------------------------------------- valve and flow
    @property
    def flow_gain_m3_s(self) -> float:
        """Kq of eq (3) at null, per unit spool: Qr √(Ps/Δp_r) (m³/s)."""
        a, v = self.actuator, self.valve
        return v.rated_flow_m3_s * math.sqrt(
            (a.supply_pressure_pa - a.return_pressure_pa) / v.rated_pressure_drop_pa
        )

    @property
    def flow_gain_m3_s_v(self) -> float:
        """Kq of eq (3) per volt of valve command, (m³/s)/V."""
        return self.flow_gain_m3_s * self.valve.gain_per_v

    @property
    def total_leakage_m3_s_pa(self) -> float:
        """Ctc = Cip + Cep/2 of eq (5)."""
        a = self.actuator
        return a.internal_leakage_m3_s_pa + 0.5 * a.external_leakage_m3_s_pa

    @property
    def kce_m3_s_pa(self) -> float:
        """Kce = Kc + Ctc of eq (5), total flow-pressure coefficient."""
        return self.valve.null_leakage_m3_s_pa + self.total_leakage_m3_s_pa

    # ----------------------------------------------------------- position model, eq (7)
    @property
    def velocity_gain_m_s(self) -> float:
        """K0 = Kq/Ap of eq (7), per unit spool (m/s)."""
        return self.flow_gain_m3_s / self.actuator.piston_area_m2

    @property
    def hydraulic_stiffness_n_m(self) -> float:
        """Kh = 4 βe Ap² / Vt = mt ωh² (eq 8; the paper's "mt ωh" is a typo)."""
        a = self.actuator
        return 4.0 * a.bulk_modulus_pa * a.piston_area_m2**2 / a.total_volume_m3

    @property
    def hydraulic_omega_rad_s(self) -> float:
        """ωh = √(4 βe Ap² / (Vt mt)) of eq (7)."""
        return math.sqrt(self.hydraulic_stiffness_n_m / self.load.mass_kg)

    @property
    def hydraulic_freq_hz(self) -> float:
        """ωh / 2π."""
        return self.hydraulic_omega_rad_s / (2.0 * math.pi)

    @property
    def hydraulic_damping(self) -> float:
        """ζh = (Kce/Ap)√(βe mt/Vt) + (Bp/4Ap)√(Vt/(βe mt)), eq (7) with the Bp term."""
        a, m = self.actuator, self.load.mass_kg
        be, vt, ap = a.bulk_modulus_pa, a.total_volume_m3, a.piston_area_m2
        return (self.kce_m3_s_pa / ap) * math.sqrt(be * m / vt) + (
            self.load.damping_n_s_m / (4.0 * ap)
        ) * math.sqrt(vt / (be * m))

    # ----------------------------------------------------------- force model, eq (8)
    @property
    def mechanical_omega_rad_s(self) -> float:
        """ωm = √(K/mt) of eq (8), with K the specimen stiffness."""
        return math.sqrt(self.load.specimen_stiffness_n_m / self.load.mass_kg)

    @property
    def mechanical_damping(self) -> float:
        """ζm = Bp / (2√(K mt)) of eq (8); inf when K = 0."""
        k = self.load.specimen_stiffness_n_m
        if k == 0:
            return math.inf
        return self.load.damping_n_s_m / (2.0 * math.sqrt(k * self.load.mass_kg))

    @property
    def _stiffness_ratio(self) -> float:
        return self.load.specimen_stiffness_n_m / self.hydraulic_stiffness_n_m

    @property
    def force_omega0_rad_s(self) -> float:
        """ω0 = ωh √(1 + K/Kh) of eq (8)."""
        return self.hydraulic_omega_rad_s * math.sqrt(1.0 + self._stiffness_ratio)

    @property
    def force_damping0(self) -> float:
        """ζ0 = [4βe Kce / (Vt (1 + K/Kh)) + Bp/mt] / (2 ω0) of eq (8)."""
        a = self.actuator
        num = 4.0 * a.bulk_modulus_pa * self.kce_m3_s_pa / (
            a.total_volume_m3 * (1.0 + self._stiffness_ratio)
        ) + self.load.damping_n_s_m / self.load.mass_kg
        return num / (2.0 * self.force_omega0_rad_s)

    @property
    def force_omega_r_rad_s(self) -> float:
        """ωr = Kce K / [Ap² (1 + K/Kh)] of eq (8)."""
        a = self.actuator
        return (
            self.kce_m3_s_pa
            * self.load.specimen_stiffness_n_m
            / (a.piston_area_m2**2 * (1.0 + self._stiffness_ratio))
        )

    @property
    def max_actuator_force_n(self) -> float:
        """Stall force Ap (Ps − Pr)."""
        a = self.actuator
        return a.piston_area_m2 * (a.supply_pressure_pa - a.return_pressure_pa)

    @property
    def max_velocity_m_s(self) -> float:
        """No-load velocity at full spool, K0 (the valve's limit, not Table 2's)."""
        return self.velocity_gain_m_s

    def derived(self) -> dict[str, tuple[float, str, str]]:
        """Derived quantities as ``{name: (value, unit, paper symbol / equation)}``."""
        return {
            "flow_gain_m3_s_v": (self.flow_gain_m3_s_v, "(m³/s)/V", "Kq, eq (3)"),
            "kce_m3_s_pa": (self.kce_m3_s_pa, "m³/(s·Pa)", "Kce, eq (5)"),
            "velocity_gain_m_s": (self.velocity_gain_m_s, "m/s", "K0 = Kq/Ap, eq (7)"),
            "hydraulic_freq_hz": (self.hydraulic_freq_hz, "Hz", "ωh/2π, eq (7)"),
            "hydraulic_damping": (self.hydraulic_damping, "-", "ζh, eq (7)"),
            "hydraulic_stiffness_n_m": (self.hydraulic_stiffness_n_m, "N/m", "Kh, eq (8)"),
            "mechanical_omega_rad_s": (self.mechanical_omega_rad_s, "rad/s", "ωm, eq (8)"),
            "mechanical_damping": (self.mechanical_damping, "-", "ζm, eq (8)"),
            "force_omega0_rad_s": (self.force_omega0_rad_s, "rad/s", "ω0, eq (8)"),
            "force_damping0": (self.force_damping0, "-", "ζ0, eq (8)"),
            "force_omega_r_rad_s": (self.force_omega_r_rad_s, "rad/s", "ωr, eq (8)"),
            "max_actuator_force_n": (self.max_actuator_force_n, "N", "Ap (Ps − Pr)"),
        }


# --------------------------------------------------------------------------- presets
def _paper_preset() -> RigParams:
    """Table 1 and Table 3 exactly as printed.

    Kq = 0.00145 (m³/s)/V is expressed through the valve rating: with a 10 V full-scale
    command and Ps = 21 MPa, Qr = 10 V · Kq / √(Ps/Δp_r).
    """
    kq_per_v = 0.00145
    ps, dpr = 21.0e6, 7.0e6
    rated_flow = kq_per_v * 10.0 / math.sqrt(ps / dpr)
    return RigParams(
        name="paper",
        valve=ValveParams(rated_flow_m3_s=rated_flow, null_leakage_m3_s_pa=2.0e-12),
        actuator=ActuatorParams(
            piston_area_m2=1.88e-3,
            total_volume_m3=0.96e-3,
            bulk_modulus_pa=6.9e8,
            internal_leakage_m3_s_pa=4.6e-17,
            external_leakage_m3_s_pa=4.6e-17,
        ),
        load=LoadParams(mass_kg=5000.0, damping_n_s_m=25_000.0, specimen_stiffness_n_m=2.0e7),
        position=PositionPidParams(kp_v_per_m=1.2),
        acceleration=TvcParams(
            kg=0.85,
            generator_omega_rad_s=3.14,
            generator_damping=0.7,
            kdf_v_per_m=24.5,
            kvf_v_per_m_s=1.0,
            kaf_v_per_m_s2=0.025,
            kdr=1.0,
            kvr_s=0.84,
            kar_s2=0.00053,
        ),
    )


PRESETS: dict[str, str] = {
    "default": "consistent set of PAPER.md §5 (250 kg per actuator, ωh ≈ 32 Hz, ζh ≈ 0.35)",
    "paper": "Table 1 and Table 3 exactly as printed (ωh ≈ 7.2 Hz, ζh ≈ 0.12)",
}


def preset(name: str = "default") -> RigParams:
    """Return a named parameter set (see :data:`PRESETS`).

    Raises
    ------
    ParameterError
        If ``name`` is not a known preset.
    """
    if name == "default":
        return RigParams()
    if name == "paper":
        return _paper_preset()
    raise ParameterError(f"unknown preset {name!r}; choose one of {sorted(PRESETS)}")


# --------------------------------------------------------------------------- TOML
def params_to_dict(params: RigParams) -> dict[str, Any]:
    """Nested plain dict (TOML/JSON-ready) of a parameter set."""
    return dataclasses.asdict(params)


def params_from_dict(data: dict[str, Any], *, base: RigParams | None = None) -> RigParams:
    """Build a parameter set from a (possibly partial) nested dict.

    Missing sections and keys keep the values of ``base`` (the default preset when not
    given; a top-level ``preset = "paper"`` key chooses another base).

    Raises
    ------
    ParameterError
        For unknown sections or keys and for values of the wrong type or out of range
        (the message names ``section.key`` and what is accepted, see :data:`RANGES`).
    """
    if not isinstance(data, dict):
        raise ParameterError(f"parameters must be a table, got {type(data).__name__}")
    data = dict(data)
    if base is None:
        name = data.pop("preset", "default")
        if not isinstance(name, str):
            raise ParameterError(f"preset={name!r} must be the name of a preset, one of "
                                 f"{sorted(PRESETS)}")
        base = preset(name)
    else:
        data.pop("preset", None)
    changes: dict[str, Any] = {}
    sections = {f.name: f for f in fields(RigParams)}
    for key, value in data.items():
        if key not in sections:
            raise ParameterError(f"unknown parameter section {key!r}; known: {sorted(sections)}")
        if key == "name":
            if not isinstance(value, str):
                raise ParameterError(f"name={value!r} must be a string")
            changes["name"] = value
            continue
        if not isinstance(value, dict):
            raise ParameterError(f"parameter section [{key}] must be a table, "
                                 f"got {type(value).__name__} {value!r}")
        current = getattr(base, key)
        known = {f.name: f for f in fields(current)}
        for sub in value:
            if sub not in known:
                raise ParameterError(
                    f"unknown parameter {key}.{sub}; known: {sorted(known)}"
                )
        try:
            changes[key] = dataclasses.replace(current, **value)
        except (TypeError, ParameterError) as exc:
            # Name the entry as it is written in the file: ``valve.saturate``.
            text = str(exc).replace(f"{type(current).__name__}.", f"{key}.")
            text = text.replace(f"{type(current).__name__}:", f"[{key}]")
            raise ParameterError(text) from None
    return dataclasses.replace(base, **changes)


#: Largest parameter file read (bytes); a full parameter set is about 2 kB.
MAX_PARAMS_FILE_BYTES = 1 << 20


def save_params(params: RigParams, path: str | Path) -> Path:
    """Write a parameter set as TOML, atomically (whole or not at all).

    Raises
    ------
    DataError
        If the folder does not exist, ``path`` is a folder, or an existing file there is
        read-only or not a regular file.
    """
    import tomli_w

    from ehss._files import atomic_path
    from ehss.errors import DataError

    path = Path(path)
    if path.is_symlink():
        raise DataError(f"cannot write {str(path)!r}: it is a symbolic link; write to another "
                        "name (or to the file it points to)")
    if path.exists():
        if path.is_dir():
            raise DataError(f"cannot write {str(path)!r}: it is a folder")
        if not path.is_file():
            raise DataError(f"cannot write {str(path)!r}: it is not a regular file")
        if not path.stat().st_mode & 0o222:
            raise DataError(f"cannot write {str(path)!r}: the file is read-only")
    text = tomli_w.dumps(params_to_dict(params))
    try:
        with atomic_path(path) as tmp:
            tmp.write_text(text, encoding="utf-8")
    except OSError as exc:
        raise DataError(f"cannot write {str(path)!r}: {exc.strerror or exc}") from None
    return path


def load_params(path: str | Path) -> RigParams:
    """Read a (possibly partial) parameter set from a UTF-8 TOML file.

    Raises
    ------
    ParameterError
        If the file cannot be read, is not UTF-8 TOML, or holds unknown or invalid
        parameters; the message starts with the file name.
    """
    path = Path(path)
    where = f"parameter file {str(path)!r}"
    raw = read_small_file(path, where, max_bytes=MAX_PARAMS_FILE_BYTES, error=ParameterError)
    data = parse_document(raw, where, parse=tomllib.loads, syntax_error=tomllib.TOMLDecodeError,
                          syntax="TOML", kind="a parameter file", advice="; save it as UTF-8",
                          error=ParameterError)
    try:
        return params_from_dict(data)
    except ParameterError as exc:
        raise ParameterError(f"{path}: {exc}") from None


def describe_params(params: RigParams) -> list[tuple[str, str, str, str]]:
    """Rows ``(section, name, value, unit)`` for printing, derived quantities last."""
    rows: list[tuple[str, str, str, str]] = [("", "name", params.name, "")]
    for f in fields(params):
        if f.name == "name":
            continue
        section = getattr(params, f.name)
        for sf in fields(section):
            value = getattr(section, sf.name)
            text = f"{value:.6g}" if isinstance(value, float) else str(value)
            rows.append((f.name, sf.name, text, _unit(sf.name)))
    for name, (value, unit, symbol) in params.derived().items():
        rows.append(("derived", f"{name} ({symbol})", f"{value:.6g}", unit))
    return rows
