"""Tests of the excitation signals: exact levels, spectra, reproducibility, feasibility."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.testing import assert_allclose

from ehss import signals as sg
from ehss.errors import ParameterError
from ehss.params import GRAVITY_M_S2, preset

FS = 1000.0


def _out_of_band_fraction(x, fs, lo, hi):
    p = np.abs(np.fft.rfft(x - 0.0)) ** 2
    f = np.fft.rfftfreq(x.size, 1 / fs)
    out = (f < lo) | (f > hi)
    return p[out].sum() / p.sum()


def test_signal_properties():
    s = sg.step(1.0, duration_s=2.0, fs=FS)
    assert len(s) == 2000 and s.duration_s == 2.0
    assert_allclose(s.t[:3], [0.0, 1e-3, 2e-3], rtol=0, atol=1e-15)
    with pytest.raises(ValueError):
        s.values[0] = 3.0  # read-only
    assert np.asarray(s).shape == (2000,)


def test_step_edges():
    s = sg.step(0.01, duration_s=1.0, fs=FS, start_s=0.25, offset=0.002)
    assert np.all(s.values[:250] == 0.002) and np.all(s.values[250:] == 0.012)


def test_sine_fade_and_amplitude():
    s = sg.sine(2.0, 5.0, duration_s=2.0, fs=FS, ramp_s=0.2, offset=1.0)
    assert s.values[0] == 1.0
    t = s.t[200:]
    assert_allclose(s.values[200:], 1.0 + 2.0 * np.sin(2 * np.pi * 5.0 * t), atol=1e-12)


@pytest.mark.parametrize("band", [(2.0, 100.0), (0.0, 20.0), (100.0, 400.0)])
def test_band_limited_random_rms_band_and_ends(band):
    s = sg.band_limited_random(band_hz=band, duration_s=8.0, fs=FS, seed=3, rms=0.5)
    assert_allclose(np.sqrt(np.mean(s.values**2)), 0.5, rtol=1e-12)  # scaling is exact
    # projection on the band is exact up to rounding (~1e-30), far below the 1e-6 spec
    assert _out_of_band_fraction(s.values, FS, *band) < 1e-20
    # end correction solves a 4×4 system with condition up to ~1e9 for narrow low bands:
    # residuals of ~1e-12 of the RMS
    assert_allclose(s.values[[0, 1, -2, -1]], 0.0, atol=1e-10)


def test_band_limited_random_peak_and_seed():
    a = sg.band_limited_random(band_hz=(2, 100), duration_s=4.0, fs=FS, seed=7, peak=0.1)
    b = sg.band_limited_random(band_hz=(2, 100), duration_s=4.0, fs=FS, seed=7, peak=0.1)
    c = sg.band_limited_random(band_hz=(2, 100), duration_s=4.0, fs=FS, seed=8, peak=0.1)
    assert_allclose(np.max(np.abs(a.values)), 0.1, rtol=1e-12)
    assert np.array_equal(a.values, b.values) and not np.array_equal(a.values, c.values)


def test_random_does_not_touch_global_rng():
    state = np.random.get_state()  # noqa: NPY002 - inspecting the legacy global RNG
    sg.band_limited_random(band_hz=(2, 100), duration_s=1.0, fs=FS, seed=None, rms=1.0)
    sg.earthquake(duration_s=4.0, fs=FS, seed=None, peak_m_s2=1.0)
    sg.multisine(band_hz=(2, 100), duration_s=1.0, fs=FS, seed=None, rms=1.0)
    after = np.random.get_state()  # noqa: NPY002
    assert all(np.array_equal(a, b) for a, b in zip(state, after, strict=True))


def test_multisine_tones_flat_and_leakage_free():
    s = sg.multisine(band_hz=(1.0, 50.0), duration_s=2.0, fs=FS, rms=1.0, seed=5)
    spec = np.fft.rfft(s.values)
    f = np.fft.rfftfreq(s.values.size, 1 / FS)
    tones = np.isin(f, s.settings["freq_hz"])
    assert tones.sum() == s.settings["n_tones"] == 99  # 1.0, 1.5, ..., 50 Hz on a 0.5 Hz grid
    # analytic: all tones equal in magnitude, nothing else (rounding ~1e-12 of a tone)
    mags = np.abs(spec[tones])
    assert_allclose(mags, mags[0], rtol=1e-10)
    assert np.max(np.abs(spec[~tones])) < 1e-10 * mags[0]
    assert_allclose(np.sqrt(np.mean(s.values**2)), 1.0, rtol=1e-12)
    # Schroeder phases give a low crest factor (random phases give ~3-4)
    assert np.max(np.abs(s.values)) < 2.0


def test_multisine_n_tones():
    s = sg.multisine(band_hz=(1.0, 50.0), duration_s=2.0, fs=FS, peak=1.0, n_tones=10)
    assert len(s.settings["freq_hz"]) == 10
    assert s.settings["freq_hz"][0] == 1.0 and s.settings["freq_hz"][-1] == 50.0
    assert_allclose(np.max(np.abs(s.values)), 1.0, rtol=1e-12)


@pytest.mark.parametrize("method", ["linear", "log"])
def test_swept_sine_instantaneous_frequency(method):
    f0, f1, T = (0.0 if method == "linear" else 1.0), 20.0, 20.0
    s = sg.swept_sine(1.0, f0_hz=f0, f1_hz=f1, duration_s=T, fs=FS, method=method)
    t = s.t
    # analytic phase: ∫ 2π f(t) dt with f(t) = f0 + (f1 − f0) t/T or f0 (f1/f0)^(t/T)
    if method == "linear":
        phase = 2 * np.pi * (f0 * t + (f1 - f0) * t**2 / (2 * T))
    else:
        k = np.log(f1 / f0) / T
        phase = 2 * np.pi * f0 * (np.exp(k * t) - 1) / k
    assert_allclose(s.values, np.sin(phase), atol=1e-9)  # same formula as scipy: rounding
    # instantaneous frequency from zero crossings: half-periods 1/(2 f(t))
    up = np.nonzero(np.diff(np.signbit(s.values)))[0]
    tc = t[up] + s.values[up] / (s.values[up] - s.values[up + 1]) / FS
    f_mid = 0.5 / np.diff(tc)
    t_mid = 0.5 * (tc[1:] + tc[:-1])
    expected = f0 + (f1 - f0) * t_mid / T if method == "linear" else f0 * (f1 / f0) ** (t_mid / T)
    keep = t_mid > 2.0  # below 2 Hz a half period spans a noticeable frequency change
    assert_allclose(f_mid[keep], expected[keep], rtol=2e-3)  # linear interpolation of tc


def test_paper_force_sweep_is_feasible():
    g = GRAVITY_M_S2
    s = sg.swept_sine(0.75 * g, f0_hz=0.0, f1_hz=20.0, duration_s=20.0, fs=FS, offset=25 * g)
    assert_allclose([s.values.min(), s.values.max()], [24.25 * g, 25.75 * g], rtol=1e-6)
    out = sg.check_feasible(s, "force", preset())
    assert out["peak_force_n"] == pytest.approx(25.75 * g, rel=1e-6)


def test_earthquake_peak_envelope_and_displacement():
    s = sg.earthquake(duration_s=20.0, fs=FS, seed=11, peak_m_s2=3.0)
    x = s.values
    assert_allclose(np.max(np.abs(x)), 3.0, rtol=1e-12)
    # starts and ends at rest: the FFT second derivative leaves ~1e-4 of the peak at the ends
    assert abs(x[0]) < 1e-3 * 3.0 and abs(x[-1]) < 1e-3 * 3.0
    # strong motion in the middle, quiet at the end of the decay
    assert np.std(x[4000:9000]) > 5 * np.std(x[18000:19500])
    # zero-initial double integral (trapezoid) reproduces the reported displacement and
    # does not drift: it ends near zero and stays inside the stroke
    v = np.concatenate([[0.0], np.cumsum(0.5 * (x[1:] + x[:-1])) / FS])
    d = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1])) / FS])
    assert_allclose(np.max(np.abs(d)), s.settings["peak_displacement_m"], rtol=1e-2)
    assert abs(d[-1]) < 1e-3 * np.max(np.abs(d))
    assert s.settings["peak_displacement_m"] < 0.09
    info = sg.check_feasible(s, "acceleration", preset())
    assert info["peak_displacement_m"] < 0.09
    # the power is centred near the ground frequency (2.5 Hz; broad KT peak, 1/f² tail)
    f = np.fft.rfftfreq(x.size, 1 / FS)
    p = np.cumsum(np.abs(np.fft.rfft(x)) ** 2)
    f_median = f[np.searchsorted(p, 0.5 * p[-1])]
    assert 1.5 < f_median < 5.0


def test_check_feasible_position_limits():
    p = preset()
    ok = sg.sine(0.02, 1.0, duration_s=2.0, fs=FS)  # 0.126 m/s peak
    sg.check_feasible(ok, "position", p)
    with pytest.raises(ParameterError, match=r"peak displacement 0\.095 m exceeds 90%"):
        sg.check_feasible(sg.step(0.095, duration_s=1.0, fs=FS, start_s=0.0), "position", p)
    fast = sg.sine(0.02, 2.0, duration_s=2.0, fs=FS)  # 0.25 m/s > 0.2 m/s
    with pytest.raises(ParameterError, match="limits.max_velocity_m_s"):
        sg.check_feasible(fast.values, "position", p, FS)
    slow_valve = dataclasses.replace(p, valve=dataclasses.replace(
        p.valve, rated_flow_m3_s=p.valve.rated_flow_m3_s / 10))
    with pytest.raises(ParameterError, match="no-load velocity"):
        sg.check_feasible(ok, "position", slow_valve)


def test_check_feasible_acceleration_and_force_limits():
    p = preset()
    big = sg.sine(1.5 * GRAVITY_M_S2, 20.0, duration_s=1.0, fs=FS)
    with pytest.raises(ParameterError, match="limits.max_acceleration_m_s2"):
        sg.check_feasible(big, "acceleration", p)
    # 0.5 g at 1 Hz: the generator asks for ~0.12 m > 0.09 m
    low = sg.sine(0.5 * GRAVITY_M_S2, 1.0, duration_s=5.0, fs=FS)
    with pytest.raises(ParameterError, match="generated .* displacement"):
        sg.check_feasible(low, "acceleration", p)
    with pytest.raises(ParameterError, match="limits.max_force_n"):
        sg.check_feasible(np.array([0.0, 1.01 * p.limits.max_force_n]), "force", p, FS)
    rated = 2 / 3 * p.max_actuator_force_n
    strong = dataclasses.replace(p, limits=dataclasses.replace(p.limits, max_force_n=1e6))
    with pytest.raises(ParameterError, match="2/3·Ap·Ps"):
        sg.check_feasible(np.array([0.0, 1.01 * rated]), "force", strong, FS)
    with pytest.raises(ParameterError, match="loop='speed'"):
        sg.check_feasible(low, "speed", p)


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: sg.step(1.0, duration_s=-1.0, fs=FS), r"duration_s=-1.0 must be in \(0, inf\)"),
        (lambda: sg.step(float("nan"), duration_s=1.0, fs=FS), "amplitude=nan must be finite"),
        (lambda: sg.band_limited_random(band_hz=(2, 600), duration_s=1.0, fs=FS, seed=1,
                                        rms=1.0), "band_hz=.* must satisfy"),
        (lambda: sg.band_limited_random(band_hz=(2, 60), duration_s=1.0, fs=FS, seed=1),
         "exactly one"),
        (lambda: sg.multisine(band_hz=(2, 60), duration_s=1.0, fs=FS, rms=1.0, peak=1.0),
         "exactly one"),
        (lambda: sg.swept_sine(1.0, f0_hz=0.0, f1_hz=20.0, duration_s=1.0, fs=FS,
                               method="log"), "f0_hz=0.0 must be > 0"),
        (lambda: sg.sine(1.0, 600.0, duration_s=1.0, fs=FS), "freq_hz=600.0 must be below"),
    ],
)
def test_validation_messages(call, match):
    with pytest.raises(ParameterError, match=match):
        call()


@settings(max_examples=25, deadline=None)
@given(
    lo=st.floats(0.0, 50.0), width=st.floats(5.0, 200.0), peak=st.floats(1e-6, 1e3),
    seed=st.integers(0, 2**32 - 1),
)
def test_random_signals_respect_peak(lo, width, peak, seed):
    band = (lo, lo + width)
    s = sg.band_limited_random(band_hz=band, duration_s=1.0, fs=FS, seed=seed, peak=peak)
    m = sg.multisine(band_hz=band, duration_s=1.0, fs=FS, seed=seed, peak=peak)
    for x in (s.values, m.values):
        assert np.all(np.isfinite(x))
        assert_allclose(np.max(np.abs(x)), peak, rtol=1e-12)


@settings(max_examples=25, deadline=None)
@given(amp=st.floats(-1e3, 1e3), off=st.floats(-1e3, 1e3), f=st.floats(0.1, 400.0))
def test_sine_bounds(amp, off, f):
    s = sg.sine(amp, f, duration_s=0.5, fs=FS, offset=off, ramp_s=0.05)
    # offset + amp·sin rounds to half an ulp of the sum, and subtracting the offset back
    # adds another: a small amplitude on a large offset is bounded only to ~eps·|off|
    slack = 2 * np.spacing(abs(off) + abs(amp))
    assert np.all(np.abs(s.values - off) <= abs(amp) * (1 + 1e-12) + slack)


def test_records_longer_than_the_limit_are_refused():
    from ehss.signals import MAX_SAMPLES, sine

    with pytest.raises(ParameterError, match="at most 20000000"):
        sine(1.0, 5.0, duration_s=(MAX_SAMPLES + 10) / 1000.0, fs=1000.0)


def test_cli_refuses_an_impossible_duration(tmp_path, capsys):
    from ehss.cli import main

    out = tmp_path / "x.csv"
    code = main(["simulate", "--loop", "position", "--signal", "sine", "--amplitude", "1e-3",
                 "--freq", "5", "--duration", "1e9", "--out", str(out)])
    assert code == 2 and not out.exists()
    assert capsys.readouterr().err.count("\n") == 1
