"""Linear models of the rig and its three closed loops as python-control systems.

Continuous-time models follow the paper's equations literally (eqs (1), (7)–(15)); with
``discrete=True`` the closed loops are instead built the way the digital controller sees
them: the linearised plant of eqs (1), (2), (5), (6) with the valve, sampled with a
zero-order hold at ``params.timing.control_rate_hz``, ``params.timing.delay_samples``
periods of computation delay, and the controller laws exactly as implemented in
:mod:`ehss.control` (PID with filtered derivative on the measurement, TVC with the ZOH
acceleration generator, feed-forward and Tustin complementary velocity filter, the
accelerometer AC coupling).

Continuous models are :class:`control.TransferFunction` objects. Discrete models are
:class:`control.StateSpace` objects with ``dt`` set: their poles cluster near z = 1
(integrators, the 0.5 Hz acceleration generator and accelerometer high-pass), where a
polynomial (transfer-function) form of order ~10 loses most of its digits; the state-space
form evaluates accurately. Both work with ``control.frequency_response``,
``control.step_response``, :func:`response_at` and :func:`margins`.

Units: valve commands in volts, spool normalised (u = 1 full opening), displacement in m,
acceleration in m/s², force in N.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import control as ct
import numpy as np
from numpy.typing import ArrayLike, NDArray

from ehss._checks import check_band
from ehss.errors import ParameterError
from ehss.params import RigParams

__all__ = [
    "valve",
    "position_open_loop",
    "force_open_loop",
    "position_closed_loop",
    "acceleration_closed_loop",
    "force_closed_loop",
    "loop_gain",
    "Margins",
    "margins",
    "closed_loop_radius",
    "response_at",
    "bandwidth_hz",
    "band_deviation_db",
    "LOOPS",
]

Loop = Literal["position", "acceleration", "force"]
LOOPS: tuple[str, ...] = ("position", "acceleration", "force")


def _check_loop(loop: str) -> None:
    if loop not in LOOPS:
        raise ParameterError(f"loop={loop!r} must be one of {list(LOOPS)}")


def _tf(num: ArrayLike, den: ArrayLike) -> ct.TransferFunction:
    return ct.tf(np.atleast_1d(np.asarray(num, float)), np.atleast_1d(np.asarray(den, float)))


# --------------------------------------------------------------------------- polynomials
def _valve_den(params: RigParams) -> NDArray[np.float64]:
    """s²/ωv² + 2ζv s/ωv + 1 of eq (1)."""
    wv, zv = params.valve.omega_rad_s, params.valve.damping
    return np.array([1.0 / wv**2, 2.0 * zv / wv, 1.0])


def _position_plant(
    params: RigParams, exact: bool = False
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Spool → displacement, eq (7) (K = 0) or eqs (5)–(6) with K = load.stiffness_n_m."""
    k = params.load.stiffness_n_m
    if k == 0.0 and not exact:
        wh, zh = params.hydraulic_omega_rad_s, params.hydraulic_damping
        # G(s) = K0 / [s (s²/ωh² + 2ζh s/ωh + 1)]                      eq (7)
        return np.array([params.velocity_gain_m_s]), np.array(
            [1.0 / wh**2, 2.0 * zh / wh, 1.0, 0.0]
        )
    # Kq Ap xv = [Ap² s + (Kce + Vt s/4βe)(mt s² + Bp s + K)] y      eqs (5), (6)
    a, ld = params.actuator, params.load
    comp = a.total_volume_m3 / (4.0 * a.bulk_modulus_pa)
    den = np.polymul([comp, params.kce_m3_s_pa], [ld.mass_kg, ld.damping_n_s_m, k])
    den = np.polyadd(den, [a.piston_area_m2**2, 0.0])
    return np.array([params.flow_gain_m3_s * a.piston_area_m2]), np.asarray(den, np.float64)


def _force_plant(params: RigParams) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Spool → Ap·PL with the specimen stiffness, eq (8) in the paper's factorised form."""
    gain = params.flow_gain_m3_s * params.actuator.piston_area_m2 / params.kce_m3_s_pa
    wr = params.force_omega_r_rad_s
    w0, z0 = params.force_omega0_rad_s, params.force_damping0
    ld = params.load
    if ld.specimen_stiffness_n_m == 0.0:
        raise ParameterError(
            "load.specimen_stiffness_n_m=0.0 must be > 0 for the force model of eq (8)"
        )
    # (s²/ωm² + 2ζm s/ωm + 1) = (mt s² + Bp s + K)/K
    num = gain * np.array([ld.mass_kg, ld.damping_n_s_m, ld.specimen_stiffness_n_m]) / (
        ld.specimen_stiffness_n_m
    )
    # GF = (Kq Ap/Kce)(s²/ωm² + 2ζm s/ωm + 1) / [(s/ωr + 1)(s²/ω0² + 2ζ0 s/ω0 + 1)]  eq (8)
    den = np.polymul([1.0 / wr, 1.0], [1.0 / w0**2, 2.0 * z0 / w0, 1.0])
    return num, np.asarray(den, np.float64)


# --------------------------------------------------------------------------- open loops
def valve(params: RigParams) -> ct.TransferFunction:
    """Servo valve, eq (1): command voltage → normalised spool position.

    .. math:: G_{sv}(s) = \\frac{K_v}{s^2/\\omega_v^2 + 2\\zeta_v s/\\omega_v + 1},
              \\quad K_v = 1/V_{fs}

    Examples
    --------
    >>> import ehss, ehss.linear as lin
    >>> float(lin.valve(ehss.preset()).dcgain())
    0.1
    """
    return _tf([params.valve.gain_per_v], _valve_den(params))


def position_open_loop(params: RigParams, *, exact: bool = False) -> ct.TransferFunction:
    """Spool → displacement (m), eq (7).

    .. math:: G(s) = \\frac{K_0}{s\\,(s^2/\\omega_h^2 + 2\\zeta_h s/\\omega_h + 1)},
              \\quad K_0 = K_q/A_p

    With ``exact=True`` or ``load.stiffness_n_m > 0`` the cubic of eqs (5)–(6) is used:

    .. math:: \frac{y}{x_v} = \frac{K_q A_p}{A_p^2 s + (K_{ce} + V_t s/4\beta_e)
              (m_t s^2 + B_p s + K)}

    Eq (7) is its K = 0 case less the term Kce·Bp/Ap² next to 1, which the paper neglects;
    for the default rig it is 0.10, so the literal eq (7) overstates the velocity gain by
    10 % and ωh by 5 %. The discrete models (what the controller sees, and what the
    simulator integrates) always use the exact form.
    """
    return _tf(*_position_plant(params, exact))


def force_open_loop(params: RigParams) -> ct.TransferFunction:
    """Spool → actuator force Ap·PL (N) against the specimen stiffness, eq (8).

    .. math:: G_F(s) = \\frac{K_q A_p}{K_{ce}}
              \\frac{s^2/\\omega_m^2 + 2\\zeta_m s/\\omega_m + 1}
              {(s/\\omega_r + 1)(s^2/\\omega_0^2 + 2\\zeta_0 s/\\omega_0 + 1)}

    The paper's factorisation differs from the exact cubic of eqs (5)–(6) by less than
    2 % in magnitude for the default rig.
    """
    return _tf(*_force_plant(params))


# --------------------------------------------------------------------------- controllers
def _pid_polys(
    kp: float, ki: float, kd: float, filter_hz: float
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Continuous PID as (n_e, n_fb, d): u = n_e/d · r − n_fb/d · y.

    u = (kp + ki/s) e − kd s/(τ s + 1) y, τ = 1/(2π f_D) (derivative on measurement).
    """
    tau = 1.0 / (2.0 * math.pi * filter_hz)
    d = np.array([1.0])
    n_e = np.array([kp])
    if ki > 0:
        n_e = np.array([kp, ki])
        d = np.array([1.0, 0.0])
    n_fb = n_e.copy()
    if kd > 0:
        n_e = np.polymul(n_e, [tau, 1.0])
        n_fb = np.polyadd(n_e, np.polymul(d, [kd, 0.0]))
        d = np.polymul(d, [tau, 1.0])
    return n_e, n_fb, d


def _closed(
    n_p: NDArray[np.float64],
    d_p: NDArray[np.float64],
    n_e: NDArray[np.float64],
    n_fb: NDArray[np.float64],
    d_c: NDArray[np.float64],
) -> ct.TransferFunction:
    # T = P Ce / (1 + P Cfb) = n_p n_e / (d_p d_c + n_p n_fb)
    return _tf(np.polymul(n_p, n_e), np.polyadd(np.polymul(d_p, d_c), np.polymul(n_p, n_fb)))


def _with_valve(
    params: RigParams, n_p: NDArray[np.float64], d_p: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Valve (eq (1)) in series: the numerator times Kv, the denominator times its poles."""
    return params.valve.gain_per_v * n_p, np.asarray(np.polymul(_valve_den(params), d_p),
                                                     np.float64)


def _pid_gains(params: RigParams, loop: str) -> tuple[float, float, float, float]:
    """(kp, ki, kd, derivative filter in Hz) of the position or the force PID."""
    if loop == "position":
        g = params.position
        return g.kp_v_per_m, g.ki_v_per_m_per_s, g.kd_v_s_per_m, g.derivative_filter_hz
    f = params.force
    return f.kp_v_per_n, f.ki_v_per_n_per_s, f.kd_v_s_per_n, f.derivative_filter_hz


# --------------------------------------------------------------------------- discrete
def _physical_plant(params: RigParams, loop: str) -> ct.StateSpace:
    """Continuous state space of eqs (1), (2), (5), (6): command (V) → measured outputs.

    States: spool xv, spool rate, displacement y, velocity ẏ, force F = Ap·PL and, for the
    acceleration loop with an AC-coupled accelerometer, the high-pass state. Outputs:
    position → y; force → F; acceleration → (y, a_m).
    """
    v, a, ld = params.valve, params.actuator, params.load
    wv, zv = v.omega_rad_s, v.damping
    k = ld.specimen_stiffness_n_m if loop == "force" else ld.stiffness_n_m
    ap, m, bp = a.piston_area_m2, ld.mass_kg, ld.damping_n_s_m
    kq, kce = params.flow_gain_m3_s, params.kce_m3_s_pa
    c_h = 4.0 * a.bulk_modulus_pa / a.total_volume_m3
    A = np.zeros((5, 5))
    # ẍv = ωv² (Kv V − xv) − 2 ζv ωv ẋv                                   eq (1)
    A[0, 1] = 1.0
    A[1, 0] = -(wv**2)
    A[1, 1] = -2.0 * zv * wv
    # ẏ
    A[2, 3] = 1.0
    # mt ÿ = F − Bp ẏ − K y                                              eq (6)
    A[3, 2], A[3, 3], A[3, 4] = -k / m, -bp / m, 1.0 / m
    # (Vt/4βe) ṖL = Kq xv − Kce PL − Ap ẏ, times Ap for F = Ap PL      eqs (2), (5)
    A[4, 0], A[4, 3], A[4, 4] = c_h * ap * kq, -c_h * ap**2, -c_h * kce
    B = np.zeros((5, 1))
    B[1, 0] = wv**2 * v.gain_per_v
    if loop == "position":
        C = np.array([[0.0, 0.0, 1.0, 0.0, 0.0]])
    elif loop == "force":
        C = np.array([[0.0, 0.0, 0.0, 0.0, 1.0]])
    else:
        acc = A[3]  # a = ÿ = row 3 of A·x
        w_hp = 2.0 * math.pi * params.sensors.accel_highpass_hz
        if w_hp > 0:
            # a_m = s/(s + ω_hp) a: state q, q̇ = a − ω_hp q, a_m = a − ω_hp q
            A6 = np.zeros((6, 6))
            A6[:5, :5] = A
            A6[5, :5] = acc
            A6[5, 5] = -w_hp
            A = A6
            B = np.vstack([B, [[0.0]]])
            C = np.zeros((2, 6))
            C[0, 2] = 1.0
            C[1, :5] = acc
            C[1, 5] = -w_hp
        else:
            C = np.vstack([[0.0, 0.0, 1.0, 0.0, 0.0], acc])
    return ct.ss(A, B, C, np.zeros((C.shape[0], 1)))


def _delay(n: int, dt: float) -> ct.StateSpace:
    """z^-n as a state space (identity gain when n = 0)."""
    if n == 0:
        return ct.ss([], [], [], [[1.0]], dt)
    A = np.eye(n, k=-1)
    B = np.zeros((n, 1))
    B[0, 0] = 1.0
    C = np.zeros((1, n))
    C[0, -1] = 1.0
    return ct.ss(A, B, C, [[0.0]], dt)


def _sampled_plant(params: RigParams, loop: str) -> ct.StateSpace:
    """Plant + valve + ZOH + computation delay: drive computed at k → sensors at k."""
    dt = params.timing.dt_s
    plant = ct.c2d(_physical_plant(params, loop), dt, method="zoh")
    return plant * _delay(params.timing.delay_samples, dt)


def _pid_discrete(kp: float, ki: float, kd: float, filter_hz: float,
                  dt: float) -> tuple[ct.StateSpace, ct.StateSpace]:
    """Discrete PID of the controller laws: (Ce on e, Cfb on y), both StateSpace.

    I[k] = I[k−1] + ki e[k] dt                       → ki dt z/(z − 1)
    D[k] = τ/(τ+dt) D[k−1] − kd/(τ+dt)(y[k] − y[k−1]) → −kd (z − 1)/((τ+dt) z − τ)
    u = kp e + I + D, so u = Ce(z) r − Cfb(z) y with Ce = kp + I, Cfb = Ce + kd(...).
    """
    tau = 1.0 / (2.0 * math.pi * filter_hz)
    ce = ct.tf([kp], [1.0], dt)
    if ki > 0:
        ce = ce + ct.tf([ki * dt, 0.0], [1.0, -1.0], dt)
    cfb = ce
    if kd > 0:
        cfb = ce + ct.tf([kd, -kd], [tau + dt, -tau], dt)
    return ct.ss(ce), ct.ss(cfb)


def _generator_discrete(params: RigParams) -> ct.StateSpace:
    """ZOH acceleration generator of eq (10): a_r → (r_d, v_d, a_d)."""
    t = params.acceleration
    wg = 2.0 * t.generator_damping * t.generator_omega_rad_s
    dg = t.generator_omega_rad_s**2
    A = np.array([[0.0, 1.0], [-dg, -wg]])
    B = np.array([[0.0], [t.kg]])
    C = np.array([[1.0, 0.0], [0.0, 1.0], [-dg, -wg]])
    D = np.array([[0.0], [0.0], [t.kg]])
    return ct.c2d(ct.ss(A, B, C, D), params.timing.dt_s, method="zoh")


def _tvc_feedback_discrete(params: RigParams) -> ct.StateSpace:
    """(y_m, a_m) → Kdf y + Kvf v̂ + Kaf a_m, v̂ = (ωc s y + a)/(s + ωc) by Tustin."""
    t = params.acceleration
    wc = 2.0 * math.pi * t.velocity_crossover_hz
    hy = ct.c2d(ct.tf([wc, 0.0], [1.0, wc]), params.timing.dt_s, method="tustin")
    ha = ct.c2d(ct.tf([1.0], [1.0, wc]), params.timing.dt_s, method="tustin")
    on_y = ct.ss(t.kdf_v_per_m + t.kvf_v_per_m_s * hy)
    on_a = ct.ss(t.kaf_v_per_m_s2 + t.kvf_v_per_m_s * ha)
    add = ct.ss([], [], [], [[1.0, 1.0]], params.timing.dt_s)
    return add * ct.append(on_y, on_a)


def _tvc_feedforward_discrete(params: RigParams) -> ct.StateSpace:
    """a_r → Kdf (Kdr r_d + Kvr v_d + Kar a_d), eqs (10), (12)."""
    t = params.acceleration
    gen = _generator_discrete(params)
    w = t.kdf_v_per_m * np.array([[t.kdr, t.kvr_s, t.kar_s2]])
    return ct.ss(gen.A, gen.B, w @ gen.C, w @ gen.D, gen.dt)


# --------------------------------------------------------------------------- closed loops
def position_closed_loop(params: RigParams, *, discrete: bool = False,
                         exact: bool = False) -> ct.LTI:
    """Reference displacement → measured displacement, eq (9).

    Continuous:

    .. math:: G_{pc}(s) = \\frac{K_v K_d K_0}{s (s^2/\\omega_v^2 + 2\\zeta_v s/\\omega_v + 1)
              (s^2/\\omega_h^2 + 2\\zeta_h s/\\omega_h + 1) + K_v K_d K_0}

    with Kd = ``position.kp_v_per_m``; a nonzero ``ki``/``kd`` adds (kp + ki/s) on the error
    and kd s/(τs + 1) on the measurement.

    Parameters
    ----------
    params : RigParams
    discrete : bool
        Build the sampled loop the controller sees (ZOH, delay, discrete PID, exact plant
        of eqs (5)–(6)); returns a :class:`control.StateSpace` with ``dt``.
    exact : bool
        Continuous model only: use the exact plant cubic (see :func:`position_open_loop`).
    """
    gains = _pid_gains(params, "position")
    if discrete:
        return _pid_loop_discrete(params, "position", gains)
    return _closed(*_with_valve(params, *_position_plant(params, exact)), *_pid_polys(*gains))


def force_closed_loop(params: RigParams, *, discrete: bool = False) -> ct.LTI:
    """Reference force → load-cell force, eqs (14)–(15): Gcf Gsv GF / (1 + Gcf Gsv GF).

    Gcf is the PID of ``params.force`` (derivative on the measurement); see
    :func:`position_closed_loop` for ``discrete``.
    """
    gains = _pid_gains(params, "force")
    if discrete:
        return _pid_loop_discrete(params, "force", gains)
    return _closed(*_with_valve(params, *_force_plant(params)), *_pid_polys(*gains))


def _pid_loop_discrete(params: RigParams, loop: str,
                       gains: tuple[float, float, float, float]) -> ct.StateSpace:
    """Sampled PID loop: the controller's error path ``ce`` closed around the plant by its
    derivative-on-measurement path ``cfb`` (ZOH, delay and valve in the plant)."""
    ce, cfb = _pid_discrete(*gains, params.timing.dt_s)
    return ct.feedback(_sampled_plant(params, loop), cfb) * ce


def acceleration_closed_loop(
    params: RigParams, *, discrete: bool = False, exact: bool = False
) -> ct.LTI:
    """Reference acceleration → measured acceleration of the TVC loop, eqs (10)–(13).

    Continuous (ideal sensors, so v̂ = s y):

    .. math::
        \\frac{a}{a_r} = s^2\\,G_{AR}(s)\\,K_{df} B(s)\\,
        \\frac{K_v K_0 / D(s)}{1 + K_v K_0 (K_{df} + K_{vf} s + K_{af} s^2)/D(s)}

    with G_AR = Kg/(s² + ωg s + δg) (eq 10), B = Kdr + Kvr s + Kar s² (eq 12) and
    D(s) = s (s²/ωv² + 2ζv s/ωv + 1)(s²/ωh² + 2ζh s/ωh + 1). With the pole placement of
    :func:`ehss.control.tuning.tune_tvc` and a fast valve this is eq (13),
    Kg s² Gsv / [(s² + ωg s + δg)(s/ωd + 1)].

    ``discrete=True`` adds ZOH, delay, the ZOH generator, the Tustin complementary velocity
    filter and the accelerometer high-pass (``sensors.accel_highpass_hz``).
    """
    t = params.acceleration
    if discrete:
        plant = _sampled_plant(params, "acceleration")  # outputs (y_m, a_m)
        cl = ct.feedback(plant, _tvc_feedback_discrete(params))
        return cl[1, 0] * _tvc_feedforward_discrete(params)
    n_p, d_p = _with_valve(params, *_position_plant(params, exact))
    wg = 2.0 * t.generator_damping * t.generator_omega_rad_s
    dg = t.generator_omega_rad_s**2
    n_fb = np.array([t.kaf_v_per_m_s2, t.kvf_v_per_m_s, t.kdf_v_per_m])
    b = t.kdf_v_per_m * np.array([t.kar_s2, t.kvr_s, t.kdr])
    num = np.polymul(np.polymul([t.kg, 0.0, 0.0], b), n_p)
    den = np.polymul([1.0, wg, dg], np.polyadd(d_p, np.polymul(n_p, n_fb)))
    return _tf(num, den)


def loop_gain(params: RigParams, loop: str, *, discrete: bool = True) -> ct.LTI:
    """Open-loop gain L (broken at the valve command) for gain/phase margins.

    The closed loop is stable and robust when L has the margins returned by
    :func:`margins`; L includes the valve, the plant, and (``discrete=True``) ZOH, delay and
    the discrete controller's feedback path (for the TVC: displacement, synthesised velocity
    and acceleration feedback together).

    Parameters
    ----------
    params : RigParams
    loop : {"position", "acceleration", "force"}
    discrete : bool
        Sampled loop (StateSpace with dt, default) or continuous (TransferFunction).
    """
    _check_loop(loop)
    if discrete:
        dt = params.timing.dt_s
        plant = _sampled_plant(params, loop)
        if loop == "acceleration":
            return _tvc_feedback_discrete(params) * plant
        _, cfb = _pid_discrete(*_pid_gains(params, loop), dt)
        return cfb * plant
    if loop == "acceleration":
        t = params.acceleration
        n_p, d_p = _with_valve(params, *_position_plant(params))
        n_fb = np.array([t.kaf_v_per_m_s2, t.kvf_v_per_m_s, t.kdf_v_per_m])
        return _tf(np.polymul(n_p, n_fb), d_p)
    plant_polys = _position_plant(params) if loop == "position" else _force_plant(params)
    n_p, d_p = _with_valve(params, *plant_polys)
    _, n_fb, d_c = _pid_polys(*_pid_gains(params, loop))
    return _tf(np.polymul(n_p, n_fb), np.polymul(d_p, d_c))


# --------------------------------------------------------------------------- analysis
def response_at(sys: ct.LTI, freq_hz: ArrayLike) -> NDArray[np.complex128]:
    """Complex frequency response of a SISO continuous or discrete system at ``freq_hz``.

    Evaluates G(j2πf) or G(e^{j2πf dt}); state-space systems are evaluated by solving
    (zI − A) x = B, which stays accurate where polynomial forms do not.
    """
    f = np.asarray(freq_hz, dtype=float)
    w = 2.0 * np.pi * f.ravel()
    dt = sys.dt if ct.isdtime(sys, strict=True) else None
    pts = np.exp(1j * w * dt) if dt else 1j * w
    if isinstance(sys, ct.StateSpace):
        A, B, C, D = (np.asarray(m, dtype=float) for m in (sys.A, sys.B, sys.C, sys.D))
        n = A.shape[0]
        if n == 0:
            out = np.full(pts.shape, D[0, 0], dtype=complex)
        else:
            M = pts[:, None, None] * np.eye(n) - A
            x = np.linalg.solve(M, np.broadcast_to(B.astype(complex), (pts.size, n, 1)))
            out = (C @ x)[:, 0, 0] + D[0, 0]
    else:
        num, den = np.asarray(sys.num[0][0], float), np.asarray(sys.den[0][0], float)
        out = np.polyval(num, pts) / np.polyval(den, pts)
    return out.reshape(f.shape)


@dataclass(frozen=True, kw_only=True)
class Margins:
    """Stability margins of an open loop L.

    Attributes
    ----------
    gain_margin_db : float
        −20 log10 |L| at the phase crossover with the smallest margin (inf if none).
    phase_margin_deg : float
        180° + ∠L at the gain crossover with the smallest margin (inf if |L| never
        crosses 1).
    phase_crossover_hz, gain_crossover_hz : float
        Where those margins are read (nan if none).
    """

    gain_margin_db: float
    phase_margin_deg: float
    phase_crossover_hz: float
    gain_crossover_hz: float


def _grid_hz(sys: ct.LTI, f_max_hz: float | None) -> NDArray[np.float64]:
    if ct.isdtime(sys, strict=True):
        top = 0.5 / sys.dt * (1.0 - 1e-9)
    else:
        top = f_max_hz if f_max_hz is not None else 1e4
    log_part = np.geomspace(1e-3, top, 20_000)
    return np.unique(np.concatenate([log_part, np.linspace(1.0, top, 20_000)]))


def margins(loop_tf: ct.LTI, *, f_max_hz: float | None = None) -> Margins:
    """Gain and phase margins of a SISO open loop (continuous or discrete).

    Crossovers are located on a dense frequency grid (up to Nyquist for discrete loops,
    ``f_max_hz`` or 10 kHz for continuous ones) and refined by linear interpolation; this
    avoids the polynomial root finding that fails for loops with poles near z = 1.

    Examples
    --------
    >>> import control as ct
    >>> m = margins(ct.tf([2.0], [1.0, 3.0, 3.0, 1.0]))  # 2/(s+1)³: GM = 8/2
    >>> round(m.gain_margin_db, 3)
    12.041
    """
    f = _grid_hz(loop_tf, f_max_hz)
    h = response_at(loop_tf, f)
    mag = np.abs(h)
    phase = np.unwrap(np.angle(h))
    gm_db, f_pc = math.inf, math.nan
    # phase crossings of −180° (mod 360°)
    branch = np.floor((phase + np.pi) / (2.0 * np.pi))
    for i in np.nonzero(np.diff(branch))[0]:
        target = (max(branch[i], branch[i + 1])) * 2.0 * np.pi - np.pi
        frac = (target - phase[i]) / (phase[i + 1] - phase[i])
        fc = f[i] + frac * (f[i + 1] - f[i])
        g = -20.0 * np.log10(mag[i] + frac * (mag[i + 1] - mag[i]))
        if g < gm_db:
            gm_db, f_pc = float(g), float(fc)
    pm, f_gc = math.inf, math.nan
    ldb = 20.0 * np.log10(mag)
    for i in np.nonzero(np.diff(np.sign(ldb)))[0]:
        frac = -ldb[i] / (ldb[i + 1] - ldb[i])
        ph = phase[i] + frac * (phase[i + 1] - phase[i])
        p = math.degrees((ph + np.pi) % (2.0 * np.pi))
        p = p - 360.0 if p > 180.0 else p
        if abs(p) < abs(pm):
            pm, f_gc = p, float(f[i] + frac * (f[i + 1] - f[i]))
    return Margins(gain_margin_db=gm_db, phase_margin_deg=pm, phase_crossover_hz=f_pc,
                   gain_crossover_hz=f_gc)


def closed_loop_radius(params: RigParams, loop: str) -> float:
    """Largest pole radius of the sampled ``loop`` closed around the rig of ``params``.

    The loop gain L of :func:`loop_gain` (valve, plant, hold, delay and the controller,
    broken at the valve command) closed by unity negative feedback, L/(1 + L): the
    linearised loop is stable when the radius is below 1. A rig of other mass, valve or
    actuator than the one its gains were designed for can leave it above 1
    (:mod:`ehss.control.tuning` designs gains for it).

    Examples
    --------
    >>> from ehss.params import preset
    >>> closed_loop_radius(preset("default"), "position") < 1.0
    True
    """
    gain = loop_gain(params, loop, discrete=True)
    return float(np.max(np.abs(ct.poles(ct.feedback(gain, 1)))))


def band_deviation_db(sys: ct.LTI, f_lo_hz: float, f_hi_hz: float, *,
                      n: int = 2000) -> tuple[float, float]:
    """(min, max) of 20 log10 |G| over [f_lo_hz, f_hi_hz] (a 0 Hz lower end uses 1 mHz)."""
    f_lo_hz, f_hi_hz = check_band((f_lo_hz, f_hi_hz), "band")
    f = np.linspace(max(f_lo_hz, 1e-3), f_hi_hz, n)
    db = 20.0 * np.log10(np.abs(response_at(sys, f)))
    return float(db.min()), float(db.max())


def bandwidth_hz(sys: ct.LTI, *, drop_db: float = 3.0, ref_hz: float = 0.0,
                 f_max_hz: float | None = None) -> float:
    """First frequency above ``ref_hz`` where |G| leaves ±``drop_db`` of |G(ref_hz)|.

    ``ref_hz = 0`` uses the gain at 1 mHz (the DC gain of a low-pass loop); use e.g.
    ``ref_hz=10`` for the band-pass acceleration loop. Returns inf if the gain stays within
    the band up to Nyquist (discrete) or ``f_max_hz`` (continuous, default 10 kHz).
    """
    if not drop_db > 0:
        raise ParameterError(f"drop_db={drop_db!r} must be > 0")
    f = _grid_hz(sys, f_max_hz)
    f = f[f > max(ref_hz, 1e-3)]
    g0 = 20.0 * np.log10(np.abs(response_at(sys, max(ref_hz, 1e-3))))
    db = 20.0 * np.log10(np.abs(response_at(sys, f))) - g0
    out = np.nonzero(np.abs(db) > drop_db)[0]
    if out.size == 0:
        return math.inf
    i = out[0]
    if i == 0:
        return float(f[0])
    edge = math.copysign(drop_db, db[i])
    frac = (edge - db[i - 1]) / (db[i] - db[i - 1])
    return float(f[i - 1] + frac * (f[i] - f[i - 1]))
