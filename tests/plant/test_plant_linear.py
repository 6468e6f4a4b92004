"""At small amplitude, with every effect off, the nonlinear plant is the linear model.

Open loop, a tiny sine on the spool; gain and phase at the sine frequency by a
least-squares sine fit after the transients, against eq (7) (spool → displacement,
K = 0) and eq (8) (spool → force Ap·PL against the specimen stiffness).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from ehss.params import preset
from ehss.simulation import simulate_open_loop

FS = 20_000.0  # drive rate = integration rate: the ZOH is corrected for exactly below
FREQS_HZ = (1.0, 3.0, 10.0, 30.0, 100.0)
SPOOL_AMPLITUDE = 1e-3


def _linear_params():
    p = preset("default")
    return dataclasses.replace(
        p,
        valve=dataclasses.replace(p.valve, saturate=False),
        sensors=dataclasses.replace(
            p.sensors, lvdt_noise_m=0.0, accel_noise_m_s2=0.0, force_noise_n=0.0,
            quantize=False, accel_highpass_hz=0.0,
        ),
        timing=dataclasses.replace(
            p.timing, control_rate_hz=FS, internal_rate_hz=FS, delay_samples=0
        ),
    )


def _measured_response(p, f_hz, *, stiffness_n_m, signal, settle_s):
    """Complex gain of ``signal`` at f_hz relative to the spool sine."""
    n_periods = max(2, int(np.ceil(0.2 * f_hz)))
    n = int(round((settle_s + n_periods / f_hz) * FS))
    t = np.arange(n) / FS
    w = 2 * np.pi * f_hz
    spool = SPOOL_AMPLITUDE * np.sin(w * t)
    r = simulate_open_loop(spool, params=p, fs=FS, stiffness_n_m=stiffness_n_m, seed=0)
    keep = t >= t[-1] - n_periods / f_hz
    tk, yk = t[keep], r.signals[signal][keep]
    # y ≈ a sin ωt + b cos ωt + c + d t   (c, d take the integrator's offset and drift)
    basis = np.column_stack([np.sin(w * tk), np.cos(w * tk), np.ones_like(tk), tk - tk[0]])
    (a, b, _, _), *_ = np.linalg.lstsq(basis, yk, rcond=None)
    measured = (a + 1j * b) / SPOOL_AMPLITUDE  # a sin + b cos = Im[(a + jb) e^{jωt}]
    # the spool is held over each 1/FS: the ZOH passes (1 − e^{−jωT})/(jωT) at ω
    wt = w / FS
    return measured / ((1 - np.exp(-1j * wt)) / (1j * wt))


def _compare(measured, model, gain_db, phase_deg):
    err_db = 20 * np.log10(abs(measured) / abs(model))
    err_deg = np.degrees(np.angle(measured / model))
    assert abs(err_db) < gain_db and abs(err_deg) < phase_deg, (err_db, err_deg)


@pytest.mark.parametrize("f_hz", FREQS_HZ)
def test_position_plant_matches_eq7(f_hz):
    p = _linear_params()
    meas = _measured_response(p, f_hz, stiffness_n_m=0.0, signal="displacement_m", settle_s=0.25)
    s = 2j * np.pi * f_hz
    a, ld = p.actuator, p.load
    # exact linearisation of eqs (5)–(6), K = 0:
    # y/u = Kq Ap / [Ap² s + (Kce + Vt s/4βe)(mt s² + Bp s)]
    exact = p.flow_gain_m3_s * a.piston_area_m2 / (
        a.piston_area_m2**2 * s
        + (p.kce_m3_s_pa + a.total_volume_m3 * s / (4 * a.bulk_modulus_pa))
        * (ld.mass_kg * s**2 + ld.damping_n_s_m * s)
    )
    # small-amplitude nonlinearity (volume change, orifice root) and RK4: ≪ 0.05 dB / 0.3°
    _compare(meas, exact, 0.05, 0.3)
    # eq (7) as printed, from the derived properties: K0/[s(s²/ωh² + 2ζh s/ωh + 1)].
    # It drops Kce·Bp/Ap² (0.10 for this rig) next to 1, which moves ωh by 5 %: 1 dB / 5°
    # hold away from the oil-column resonance; at 30 Hz (next to ωh/2π = 32 Hz) the
    # literal eq (7) itself is 8° away from the exact linearisation checked above.
    if 20.0 < f_hz < 50.0:
        return
    wh, zh = p.hydraulic_omega_rad_s, p.hydraulic_damping
    eq7 = p.velocity_gain_m_s / (s * (s**2 / wh**2 + 2 * zh * s / wh + 1))
    _compare(meas, eq7, 1.0, 5.0)


@pytest.mark.parametrize("f_hz", FREQS_HZ)
def test_force_plant_matches_eq8(f_hz):
    p = _linear_params()
    k = p.load.specimen_stiffness_n_m
    meas = _measured_response(p, f_hz, stiffness_n_m=k, signal="force_n", settle_s=0.8)
    s = 2j * np.pi * f_hz
    a, ld = p.actuator, p.load
    mech = ld.mass_kg * s**2 + ld.damping_n_s_m * s + k
    # exact: F/u = Kq Ap (mt s² + Bp s + K) / [Ap² s + (Kce + Vt s/4βe)(mt s² + Bp s + K)]
    exact = p.flow_gain_m3_s * a.piston_area_m2 * mech / (
        a.piston_area_m2**2 * s
        + (p.kce_m3_s_pa + a.total_volume_m3 * s / (4 * a.bulk_modulus_pa)) * mech
    )
    _compare(meas, exact, 0.05, 0.3)
    # eq (8) in the paper's factorised form, from the derived properties
    wm, zm = p.mechanical_omega_rad_s, p.mechanical_damping
    w0, z0, wr = p.force_omega0_rad_s, p.force_damping0, p.force_omega_r_rad_s
    eq8 = (p.flow_gain_m3_s * a.piston_area_m2 / p.kce_m3_s_pa) * (
        s**2 / wm**2 + 2 * zm * s / wm + 1
    ) / ((s / wr + 1) * (s**2 / w0**2 + 2 * z0 * s / w0 + 1))
    _compare(meas, eq8, 1.0, 5.0)


def test_matches_ehss_linear():
    """The same check through ehss.linear (exact cubic and eq (8) transfer functions)."""
    import ehss.linear as lin
    p = _linear_params()
    for f_hz in (2.0, 40.0):
        meas = _measured_response(p, f_hz, stiffness_n_m=0.0, signal="displacement_m",
                                  settle_s=0.25)
        model = complex(lin.position_open_loop(p, exact=True)(2j * np.pi * f_hz))
        _compare(meas, model, 0.05, 0.3)
