"""Default controller tunings of the three loops, derived from the linear models.

Each ``tune_*`` function designs on the *discrete* loop the controller actually closes
(:mod:`ehss.linear` with ``discrete=True``: valve, exact plant of eqs (5)–(6), zero-order
hold, ``timing.delay_samples`` of delay, the discrete controller law) and returns a
parameter section that :func:`dataclasses.replace` puts into a :class:`~ehss.params.RigParams`.
The defaults in :mod:`ehss.params` are these results for ``preset("default")``, rounded to
4 significant digits.

Requirements (Table 2): closed loops within ±3 dB over position 0–20 Hz, acceleration
1–50 Hz, force 0–20 Hz, each with a gain margin of at least 6 dB
(:data:`REQUIRED_GAIN_MARGIN_DB`). The designs aim at ``gain_margin_db`` =
:data:`DESIGN_GAIN_MARGIN_DB`, leaving 0.5 dB for rounding and model error. Position and
force meet their bands; the acceleration band cannot be met at 6 dB gain margin with the
paper's TVC structure (see :func:`tune_tvc`).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from scipy.optimize import brentq

from ehss import linear
from ehss._checks import check_real
from ehss.errors import ParameterError
from ehss.params import ForcePidParams, PositionPidParams, RigParams, TvcParams

__all__ = ["tune_position", "tune_tvc", "tune_force", "tvc_pole_placement",
           "REQUIRED_GAIN_MARGIN_DB", "DESIGN_GAIN_MARGIN_DB"]

#: Gain margin Table 2 requires of every sampled loop, dB.
REQUIRED_GAIN_MARGIN_DB = 6.0
#: Gain margin every tuning aims at, dB: the required one and 0.5 dB for rounding and
#: model error.
DESIGN_GAIN_MARGIN_DB = REQUIRED_GAIN_MARGIN_DB + 0.5


def _check_gm(gain_margin_db: float) -> None:
    check_real(gain_margin_db, "gain_margin_db", lo=0.0, hi=40.0, lo_open=True, hi_open=True)


def _scale_to_margin(params: RigParams, loop: str, target_db: float) -> float:
    """Factor by which the loop gain may be multiplied to give ``target_db`` of margin."""
    gm = linear.margins(linear.loop_gain(params, loop, discrete=True)).gain_margin_db
    if not math.isfinite(gm):
        raise ParameterError(f"the {loop} loop has no phase crossover; cannot set its gain")
    return 10.0 ** ((gm - target_db) / 20.0)


def tune_position(
    params: RigParams,
    *,
    gain_margin_db: float = DESIGN_GAIN_MARGIN_DB,
    integral_ratio: float = 0.05,
) -> PositionPidParams:
    """Position PI gains from the discrete loop's gain margin, eq (9).

    Parameters
    ----------
    params : RigParams
        Rig whose valve, plant and timing are designed for (its own position gains are
        ignored, its derivative filter and output limit kept).
    gain_margin_db : float
        Design gain margin of the sampled loop (Table 2 asks for ≥ 6 dB).
    integral_ratio : float
        Integral corner ωi as a fraction of the P-loop crossover Kv·Kd·K0 (0 = P only).

    Returns
    -------
    PositionPidParams

    Notes
    -----
    The P loop of eq (9) is L = Kd·Kv·K0 / [s (…valve…)(s²/ωh² + 2ζh s/ωh + 1)]. Without
    valve and delay its gain margin is 2ζh ωh/(Kv Kd K0); with the valve, ZOH and one
    sample of delay the phase reaches −180° below ωh (about 26 Hz for the default rig),
    where the oil-column resonance still lifts |L|. L is proportional to Kd, so

    .. math:: K_d = 10^{(GM_1 - GM)/20}

    with GM₁ the margin at Kd = 1 V/m. A small integral action ωi = ``integral_ratio``·
    Kv·Kd·K0 (ki = Kd·ωi) removes the steady-state error caused by valve null bias, load
    stiffness and friction; the type-1 plant already follows steps without it. With ωi
    fixed the loop is again proportional to Kd, which is rescaled to the exact target.
    The oil-column peak keeps the closed loop near −1.5 dB at 20 Hz although the
    crossover is only ≈ 8 Hz.
    """
    _check_gm(gain_margin_db)
    if not 0 <= integral_ratio < 1:
        raise ParameterError(f"integral_ratio={integral_ratio!r} must be in [0, 1)")
    pos = dataclasses.replace(params.position, kp_v_per_m=1.0, ki_v_per_m_per_s=0.0,
                              kd_v_s_per_m=0.0)
    p = dataclasses.replace(params, position=pos)
    kp = _scale_to_margin(p, "position", gain_margin_db)
    # ωi = r · Kv Kd K0 (a decade and more below the crossover)
    w_i = integral_ratio * params.valve.gain_per_v * kp * params.velocity_gain_m_s
    pos = dataclasses.replace(pos, ki_v_per_m_per_s=w_i)  # ki = kp ωi with kp = 1
    kp = _scale_to_margin(dataclasses.replace(p, position=pos), "position", gain_margin_db)
    return dataclasses.replace(pos, kp_v_per_m=kp, ki_v_per_m_per_s=kp * w_i)


def tune_force(
    params: RigParams, *, gain_margin_db: float = DESIGN_GAIN_MARGIN_DB
) -> ForcePidParams:
    """Force PI gains: zero on the pressure pole ωr of eq (8), gain from the margin.

    Notes
    -----
    Eq (8) has a low real pole ωr = Kce K/[Ap²(1 + K/Kh)] (4.4 Hz for the default
    rig) below the mechanical zeros ωm and hydraulic poles ω0. The PI
    Gcf = kp (1 + ωr/s), ki = kp ωr, cancels it, so that

    .. math:: L(s) \\approx \\frac{K_v k_p K_q A_p \\omega_r / K_{ce}}{s}
              \\frac{s^2/\\omega_m^2 + 2\\zeta_m s/\\omega_m + 1}
              {s^2/\\omega_0^2 + 2\\zeta_0 s/\\omega_0 + 1}

    is an integrator up to the zero/pole pair, and the closed loop a first-order lag
    whose bandwidth is the crossover. L is proportional to kp, so kp is set to give
    ``gain_margin_db`` on the discrete loop (phase crossover ≈ 77 Hz), which puts the
    −3 dB point near 27 Hz.
    """
    _check_gm(gain_margin_db)
    w_r = params.force_omega_r_rad_s
    f = dataclasses.replace(params.force, kp_v_per_n=1.0, ki_v_per_n_per_s=w_r,
                            kd_v_s_per_n=0.0)
    kp = _scale_to_margin(dataclasses.replace(params, force=f), "force", gain_margin_db)
    return dataclasses.replace(f, kp_v_per_n=kp, ki_v_per_n_per_s=kp * w_r)


def tvc_pole_placement(
    params: RigParams,
    omega_d_rad_s: float,
    *,
    omega_nc_ratio: float = 1.05,
    damping_nc: float = 0.7,
) -> dict[str, float]:
    """TVC feedback and feed-forward gains for a given acceleration bandwidth ωd.

    Returns ``{"kdf_v_per_m", "kvf_v_per_m_s", "kaf_v_per_m_s2", "kdr", "kvr_s", "kar_s2"}``.

    Notes
    -----
    The exact position plant of eqs (5)–(6) is y/xv = b0 / (a3 s³ + a2 s² + a1 s + a0)
    (eq (7) when a0 = 0 and Kce·Bp ≪ Ap²). With Kl = Kv b0, the displacement, velocity
    and acceleration feedback make the characteristic polynomial

    .. math:: a_3 s^3 + a_2 s^2 + a_1 s + a_0 + K_l (K_{df} + K_{vf} s + K_{af} s^2)
              = c\\,(s/\\omega_d + 1)(s^2/\\omega_{nc}^2 + 2\\zeta_{nc} s/\\omega_{nc} + 1)

    (eq (11)), so c = a3 ωd ωnc², Kaf = [c(2ζnc/(ωd ωnc) + 1/ωnc²) − a2]/Kl,
    Kvf = [c(1/ωd + 2ζnc/ωnc) − a1]/Kl, Kdf = (c − a0)/Kl, with ωnc = ``omega_nc_ratio``·ωh.
    The feed-forward of eq (12), B(s) = Kdr (s²/ωnc² + 2ζnc s/ωnc + 1) with
    Kdr = c/(c − a0) (= 1 on a free table), cancels the closed-loop oil-column pair so that
    y/r_d = 1/(s/ωd + 1) and a/a_r follows eq (13).
    """
    if not omega_d_rad_s > 0:
        raise ParameterError(f"omega_d_rad_s={omega_d_rad_s!r} must be > 0")
    if not 1.0 <= omega_nc_ratio <= 1.5:
        raise ParameterError(f"omega_nc_ratio={omega_nc_ratio!r} must be in [1, 1.5]")
    if not 0 < damping_nc < 2:
        raise ParameterError(f"damping_nc={damping_nc!r} must be in (0, 2)")
    n, d = linear._position_plant(params, exact=True)
    a3, a2, a1, a0 = (float(x) for x in d)
    kl = params.valve.gain_per_v * float(n[0])
    wd, zn = omega_d_rad_s, damping_nc
    wnc = omega_nc_ratio * params.hydraulic_omega_rad_s
    c = a3 * wd * wnc**2
    kdr = c / (c - a0)
    return {
        "kdf_v_per_m": (c - a0) / kl,
        "kvf_v_per_m_s": (c * (1.0 / wd + 2.0 * zn / wnc) - a1) / kl,
        "kaf_v_per_m_s2": (c * (2.0 * zn / (wd * wnc) + 1.0 / wnc**2) - a2) / kl,
        "kdr": kdr,
        "kvr_s": kdr * 2.0 * zn / wnc,
        "kar_s2": kdr / wnc**2,
    }


def tune_tvc(
    params: RigParams,
    *,
    gain_margin_db: float = DESIGN_GAIN_MARGIN_DB,
    omega_nc_ratio: float = 1.05,
    damping_nc: float = 0.7,
    kg: float = TvcParams.kg,
    generator_omega_rad_s: float = TvcParams.generator_omega_rad_s,
    generator_damping: float = TvcParams.generator_damping,
) -> TvcParams:
    """TVC gains by pole placement (eqs (10)–(13)) with the widest ωd the margin allows.

    Parameters
    ----------
    params : RigParams
    gain_margin_db : float
        Design gain margin of the sampled loop.
    omega_nc_ratio, damping_nc : float
        ωnc/ωh (1.05–1.2 in the paper) and ζnc (≈ 0.7) of eq (11).
    kg, generator_omega_rad_s, generator_damping : float
        Kg, ωn, ζn of the acceleration generator, eq (10); by default those of
        :class:`~ehss.params.TvcParams` (Table 3: ωn = 3.14 rad/s, ζn = 0.7).

    Notes
    -----
    For each ωd the gains follow :func:`tvc_pole_placement`; the gain margin of the
    discrete loop decreases monotonically with ωd, and ωd is found by Brent's method so that
    the margin equals ``gain_margin_db``.

    Why the 50 Hz band is out of reach: above ωh the acceleration feedback dominates and
    L ≈ Kl Kaf ωh'²/s · Gsv · e^{−1.5 s T} (ZOH and one sample of delay), with
    Kl Kaf ωh'² ≈ 2ζnc ωnc − 2ζh ωh + ωd ≥ 156 rad/s even for ωd → 0. Valve (120 Hz)
    and 1.5 ms of effective delay bring the phase to −180° near 76 Hz (≈ 480 rad/s), so
    |L| ≤ 0.5 there limits ωd to ≈ 2π·11 Hz. Then y/r_d ≈ 1/(s/ωd + 1): the discrete
    closed loop stays within ±3 dB only from 1 Hz to ≈ 13 Hz and sags to ≈ −9.6 dB
    between 30 and 50 Hz. Reaching
    50 Hz needs ωd ≳ 2π·60 Hz, i.e. a phase crossover above ≈ 150 Hz: a faster valve
    and a shorter loop delay.
    """
    _check_gm(gain_margin_db)
    base = dataclasses.replace(
        params.acceleration, kg=kg, generator_omega_rad_s=generator_omega_rad_s,
        generator_damping=generator_damping,
    )

    def build(wd: float) -> TvcParams:
        gains = tvc_pole_placement(params, wd, omega_nc_ratio=omega_nc_ratio,
                                   damping_nc=damping_nc)
        return dataclasses.replace(base, **gains)

    def gm(wd: float) -> float:
        p = dataclasses.replace(params, acceleration=build(wd))
        return linear.margins(linear.loop_gain(p, "acceleration")).gain_margin_db

    lo, hi = 2.0 * math.pi * 0.05, 2.0 * math.pi * 500.0
    if gm(lo) < gain_margin_db:
        raise ParameterError(
            f"gain_margin_db={gain_margin_db!r} cannot be reached by the TVC even with "
            f"ωd = {lo:.3g} rad/s"
        )
    if gm(hi) >= gain_margin_db:
        return build(hi)
    # the margin falls monotonically and continuously with ωd: Brent's method on log ωd
    # (about 10 margin evaluations instead of bisection's 28 for the same 4e-8)
    log_wd = brentq(lambda x: gm(math.exp(x)) - gain_margin_db, math.log(lo), math.log(hi),
                    xtol=4e-8, rtol=4e-8)
    return build(math.exp(log_wd))


def _round_sig(x: float, digits: int = 4) -> float:
    """Round to ``digits`` significant digits (how the defaults in params.py are stored)."""
    if x == 0 or not np.isfinite(x):
        return x
    return float(f"{x:.{digits}g}")
