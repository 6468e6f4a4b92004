"""The default controller gains are the model-based tunings and meet Table 2's bands."""

from __future__ import annotations

import dataclasses
import math

import pytest
from numpy.testing import assert_allclose

from ehss import linear as lin
from ehss.control import tuning
from ehss.errors import ParameterError
from ehss.params import ForcePidParams, PositionPidParams, TvcParams, preset


@pytest.fixture(scope="module")
def tuned():
    p = preset("default")
    return {
        "position": tuning.tune_position(p),
        "force": tuning.tune_force(p),
        "acceleration": tuning.tune_tvc(p),
    }


def _gains(section):
    return {
        f.name: getattr(section, f.name)
        for f in dataclasses.fields(section)
        if isinstance(getattr(section, f.name), float)
    }


@pytest.mark.parametrize("loop", ["position", "force", "acceleration"])
def test_defaults_equal_tuning(tuned, loop):
    default = getattr(preset("default"), loop)
    for name, value in _gains(tuned[loop]).items():
        # params.py stores the tunings to 4 significant digits: relative error ≤ 5e-4
        assert_allclose(getattr(default, name), value, rtol=5e-4, err_msg=name)


@pytest.mark.parametrize("loop", ["position", "force", "acceleration"])
def test_default_gain_margin_at_least_6db(loop):
    m = lin.margins(lin.loop_gain(preset("default"), loop))
    # designed for 6.5 dB; the 4-digit rounding moves it by < 0.01 dB
    assert 6.4 < m.gain_margin_db < 6.6
    assert m.phase_margin_deg > 45.0


@pytest.mark.parametrize(("loop", "band"), [("position", (0.0, 20.0)), ("force", (0.0, 20.0))])
def test_default_bands_met(loop, band):
    fn = {"position": lin.position_closed_loop, "force": lin.force_closed_loop}[loop]
    lo, hi = lin.band_deviation_db(fn(preset("default"), discrete=True), *band)
    assert -3.0 <= lo and hi <= 3.0


@pytest.mark.slow
def test_acceleration_band_documented_shortfall():
    # Documented exception: the TVC keeps 6.5 dB of gain margin only up to ωd ≈ 2π·11 Hz,
    # so the ±3 dB band reaches from 1 Hz to ≈ 13 Hz, and the response sags to ≈ −9.6 dB
    # between 30 and 50 Hz.
    t = lin.acceleration_closed_loop(preset("default"), discrete=True)
    lo, hi = lin.band_deviation_db(t, 1.0, 50.0)
    assert_allclose(lo, -9.6, atol=0.2)  # the figure quoted in the docs
    assert -0.5 < hi <= 0.0
    assert lin.band_deviation_db(t, 1.0, 13.0)[0] > -3.0
    assert lin.band_deviation_db(t, 1.0, 13.5)[0] < -3.0
    # the shortfall is the structure's, not the margin target's: even 6 dB does not help
    p6 = dataclasses.replace(preset("default"),
                             acceleration=tuning.tune_tvc(preset("default"), gain_margin_db=6.0))
    assert lin.band_deviation_db(lin.acceleration_closed_loop(p6, discrete=True), 1, 50)[0] < -8


def test_tvc_omega_d_and_feedforward(tuned):
    p = preset("default")
    t = tuned["acceleration"]
    wnc = 1.05 * p.hydraulic_omega_rad_s
    # eq (12): Kvr = 2ζnc/ωnc, Kar = 1/ωnc², Kdr = 1 on a free table
    assert_allclose([t.kdr, t.kvr_s, t.kar_s2], [1.0, 2 * 0.7 / wnc, 1 / wnc**2], rtol=1e-12)
    # Table 3 generator
    assert (t.kg, t.generator_omega_rad_s, t.generator_damping) == (1.0, 3.14, 0.7)


def test_tvc_pole_placement_places_poles():
    p = preset("default")
    wd = 2 * math.pi * 10.0
    g = tuning.tvc_pole_placement(p, wd)
    p = dataclasses.replace(p, valve=dataclasses.replace(p.valve, natural_freq_hz=1e6),
                            acceleration=dataclasses.replace(p.acceleration, **g))
    # characteristic roots of the continuous loop (valve made ~ideal): −ωd and the
    # ωnc, ζnc pair (valve at 1 MHz shifts them by < 1e-3 relative)
    poles = lin.acceleration_closed_loop(p, exact=True).poles()
    wnc = 1.05 * p.hydraulic_omega_rad_s
    assert min(abs(poles + wd)) < 1e-3 * wd
    osc = [q for q in poles if q.imag > 1.0 and 10.0 < abs(q) < 1e4]  # not the generator
    assert len(osc) == 1
    assert_allclose(abs(osc[0]), wnc, rtol=1e-3)
    assert_allclose(-osc[0].real / abs(osc[0]), 0.7, rtol=1e-3)


def test_paper_preset_keeps_table3():
    p = preset("paper")
    assert p.position.kp_v_per_m == 1.2
    t = p.acceleration
    assert (t.kg, t.kaf_v_per_m_s2, t.kvf_v_per_m_s, t.kdf_v_per_m) == (0.85, 0.025, 1.0, 24.5)
    assert (t.kar_s2, t.kvr_s, t.kdr) == (0.00053, 0.84, 1.0)


def test_types_and_validation():
    p = preset("default")
    assert isinstance(tuning.tune_force(p), ForcePidParams)
    assert isinstance(tuning.tune_position(p, integral_ratio=0.0), PositionPidParams)
    assert tuning.tune_position(p, integral_ratio=0.0).ki_v_per_m_per_s == 0.0
    assert isinstance(tuning.tvc_pole_placement(p, 50.0)["kdf_v_per_m"], float)
    assert TvcParams  # imported type used in annotations of tune_tvc
    with pytest.raises(ParameterError, match="gain_margin_db=-1"):
        tuning.tune_force(p, gain_margin_db=-1)
    with pytest.raises(ParameterError, match="omega_d_rad_s=0"):
        tuning.tvc_pole_placement(p, 0)
