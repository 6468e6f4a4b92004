"""Discrete coefficients of the digital controllers (position PID, force PID, TVC).

The laws run at the control rate fs = 1/dt on sampled sensor signals:

* PID (position, eq (9); force, eq (15)): u = kp e + I + D, I += ki e dt with
  conditional integration, D[k] = τ/(τ+dt) D[k−1] − kd/(τ+dt)(y[k] − y[k−1]),
  τ = 1/(2π f_D) (derivative on measurement, backward Euler).
* TVC (eqs (10)–(12), Fig. 6): generator GAR(s) = Kg/(s² + ωg s + δg) discretised exactly
  with a zero-order hold (:func:`generator_zoh`), complementary velocity filter
  v̂ = (ωc s y + a)/(s + ωc) discretised with the bilinear transform
  (:func:`complementary_velocity_tustin`).
"""

from __future__ import annotations

import math
from typing import TypeVar

import numpy as np

from ehss.control._kernels import PidSettings, TvcSettings
from ehss.params import ForcePidParams, PositionPidParams, TvcParams

_Settings = TypeVar("_Settings", PidSettings, TvcSettings)

#: Settings of the three-variable controller applied as the parameters give them, under
#: the same names: Kg of eq (10), the feedback (f) and feed-forward (r) gains of
#: eqs (11)–(12) and the drive limit.
_TVC_AS_GIVEN = ("kg", "kdf_v_per_m", "kvf_v_per_m_s", "kaf_v_per_m_s2", "kdr", "kvr_s",
                 "kar_s2", "output_limit_v")

__all__ = [
    "pid_coefficients",
    "generator_coefficients",
    "generator_zoh",
    "complementary_velocity_tustin",
    "tvc_coefficients",
]


def pid_coefficients(pid: PositionPidParams | ForcePidParams, dt_s: float) -> PidSettings:
    """Discrete coefficients ``(kp, ki·dt, τ/(τ+dt), kd/(τ+dt), limit)`` of a PID.

    Parameters
    ----------
    pid : PositionPidParams or ForcePidParams
        Gains in V per metre (position) or V per newton (force).
    dt_s : float
        Control period, s.

    Returns
    -------
    PidSettings
        The coefficients by name (:class:`ehss.control.kernels.PidSettings`).
    """
    if isinstance(pid, PositionPidParams):
        kp, ki, kd = pid.kp_v_per_m, pid.ki_v_per_m_per_s, pid.kd_v_s_per_m
    else:
        kp, ki, kd = pid.kp_v_per_n, pid.ki_v_per_n_per_s, pid.kd_v_s_per_n
    tau = 1.0 / (2.0 * math.pi * pid.derivative_filter_hz)
    # float(): the kernels are compiled for float64 fields, whatever type a gain was given in
    return _floats(PidSettings(
        kp=kp,
        ki_dt=ki * dt_s,
        derivative_pole=tau / (tau + dt_s),
        derivative_gain=kd / (tau + dt_s),
        output_limit_v=pid.output_limit_v,
    ))


def _floats(settings: _Settings) -> _Settings:
    """``settings`` (a NamedTuple) with every field a Python float."""
    return type(settings)._make(float(v) for v in settings)


def _expm_small(m: np.ndarray) -> np.ndarray:
    """e^M of a small matrix by scaling and squaring of a Taylor series.

    Written out (no LAPACK) on purpose: scipy's ``expm`` wakes the BLAS thread pool,
    whose spinning threads then compete with the simulation kernel for the CPU.
    Accurate to rounding: the scaled norm is ≤ 1/4 and 20 terms leave < 1e-25.
    """
    norm = float(np.max(np.sum(np.abs(m), axis=1)))
    squarings = max(0, int(math.ceil(math.log2(norm / 0.25)))) if norm > 0.25 else 0
    a = m / 2.0**squarings
    n = m.shape[0]
    result = np.eye(n)
    term = np.eye(n)
    for k in range(1, 21):
        # term = A^k / k!
        term = _matmul(term, a) / k
        result = result + term
    for _ in range(squarings):
        result = _matmul(result, result)
    return result


def _matmul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    n = a.shape[0]
    out = np.zeros((n, n))
    for i in range(n):
        for j in range(n):
            out[i, j] = math.fsum(a[i, k] * b[k, j] for k in range(n))
    return out


def generator_zoh(kg: float, omega_g: float, delta_g: float,
                  dt_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact ZOH discretisation of the acceleration generator, eq (10).

    State [r_d, v_d] with ṙ_d = v_d, v̇_d = Kg a_r − ωg v_d − δg r_d.

    Returns
    -------
    phi : ndarray, shape (2, 2)
        e^{A dt}.
    gamma : ndarray, shape (2,)
        ∫₀^dt e^{Aτ} dτ B.

    Notes
    -----
    Computed from the exponential of the augmented matrix [[A, B], [0, 0]] dt.
    """
    m = np.zeros((3, 3))
    m[0, 1] = 1.0
    m[1, 0] = -delta_g
    m[1, 1] = -omega_g
    m[1, 2] = kg
    e = _expm_small(m * dt_s)
    return e[:2, :2].copy(), e[:2, 2].copy()


def complementary_velocity_tustin(omega_c: float, dt_s: float) -> tuple[float, float, float]:
    """Tustin form of v̂ = (ωc s y + a)/(s + ωc) (Fig. 6 velocity synthesis).

    With c = 2/dt:
    v̂[k] = p v̂[k−1] + b_y (y[k] − y[k−1]) + b_a (a[k] + a[k−1]),
    p = (c − ωc)/(c + ωc), b_y = ωc c/(c + ωc), b_a = 1/(c + ωc).

    Returns
    -------
    (p, b_y, b_a) : tuple of float
    """
    c = 2.0 / dt_s
    return (c - omega_c) / (c + omega_c), omega_c * c / (c + omega_c), 1.0 / (c + omega_c)


def generator_coefficients(tvc: TvcParams) -> tuple[float, float]:
    """(ωg, δg) of the acceleration generator GAR(s) = Kg/(s² + ωg s + δg), eq (10):
    ωg = 2 ζn ωn and δg = ωn² from the generator's natural frequency and damping."""
    wn = tvc.generator_omega_rad_s
    return 2.0 * tvc.generator_damping * wn, wn * wn


def tvc_coefficients(tvc: TvcParams, dt_s: float) -> TvcSettings:
    """Discrete coefficients of the three-variable controller at the period ``dt_s``.

    Returns
    -------
    TvcSettings
        The coefficients by name (:class:`ehss.control.kernels.TvcSettings`): the
        generator's ZOH matrices (:func:`generator_zoh`), the gains of eqs (11)–(12) and
        the velocity filter (:func:`complementary_velocity_tustin`).
    """
    wg, dg = generator_coefficients(tvc)
    phi, gam = generator_zoh(tvc.kg, wg, dg, dt_s)
    pole, by, ba = complementary_velocity_tustin(2.0 * math.pi * tvc.velocity_crossover_hz, dt_s)
    return _floats(TvcSettings(
        phi_rr=phi[0, 0],
        phi_rv=phi[0, 1],
        phi_vr=phi[1, 0],
        phi_vv=phi[1, 1],
        gamma_r=gam[0],
        gamma_v=gam[1],
        omega_g_rad_s=wg,
        delta_g_rad2_s2=dg,
        vf_pole=pole,
        vf_gain_y_1_s=by,
        vf_gain_a_s=ba,
        **{name: getattr(tvc, name) for name in _TVC_AS_GIVEN},
    ))
