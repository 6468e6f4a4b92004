"""``ehss.compensation.compensation``: one checked sequence, one result."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose

from ehss.compensation import (
    DEFAULT_MAX_GAIN,
    DEFAULT_MIN_GAIN,
    check_drive,
    compensate,
    compensation,
)
from ehss.errors import EhssWarning, ParameterError
from ehss.identification.model import ArmaxModel

FS = 1000.0


def _model(b=(0.1, 0.05), **kw):
    # q^-2 (b0 + b1 q^-1) / (1 - 1.5 q^-1 + 0.7 q^-2): minimum phase, G(1) = 0.75 for the
    # default b
    return ArmaxModel(a=[1.0, -1.5, 0.7], b=list(b), delay=2, dt=1 / FS,
                      band_hz=(0.0, 100.0), **kw)


def _reference(n=2000):
    # tones of 5-31 Hz under a Gaussian envelope: at rest at both ends, inside the band
    t = np.arange(n) / FS
    tones = np.sin(2 * np.pi * 5 * t) + 0.5 * np.sin(2 * np.pi * 13 * t + 1.0)
    return 0.01 * tones * np.exp(-(((t - 1.0) / 0.2) ** 2))


def test_drive_is_about_the_models_operating_point():
    """drive = u0 + F (r − y0): the model run on the drive's deviation gives r − y0."""
    m = _model(offsets=(2.0, 1.5))
    r = 1.5 + _reference()
    result = compensation(m, r, fs=FS)
    assert result.offsets == (2.0, 1.5) and result.warnings == ()
    # exact stable inversion in the band: rounding only (measured ~1e-17 on 0.01)
    assert_allclose(1.5 + m.simulate(result.drive - 2.0), r, rtol=0, atol=1e-12)
    assert_allclose(result.reference, r, rtol=0, atol=1e-15)
    assert result.check is not None and result.check.min_gain == DEFAULT_MIN_GAIN
    assert_allclose(compensate(m, r, fs=FS), result.drive, rtol=0, atol=0)
    # offsets=None: the reference is taken as it is, as --ignore-offsets does
    plain = compensation(m, _reference(), fs=FS, offsets=None)
    assert plain.offsets == (0.0, 0.0)
    assert_allclose(m.simulate(plain.drive), _reference(), rtol=0, atol=1e-12)


def test_min_gain_bound_is_the_max_gains_reciprocal():
    """The drive check bounds the RMS ratio from below by 1/3 (checks.py notes)."""
    assert DEFAULT_MIN_GAIN == pytest.approx(1.0 / DEFAULT_MAX_GAIN, rel=1e-15)
    r = _reference()
    check_drive(0.34 * r, r, FS)  # a loop amplifying by 9.4 dB at most: accepted
    with pytest.raises(ParameterError, match=r"RMS is 0\.01× the reference's"):
        check_drive(0.01 * r, r, FS)
    assert check_drive(0.01 * r, r, FS, min_gain=None).rms_gain == pytest.approx(0.01)


def test_huge_b_coefficients_are_refused_or_reported_when_forced():
    m = _model(b=(10.0, 5.0))  # G(1) = 75: a unit error, the drive ~1/75 of the reference
    r = _reference()
    with pytest.raises(ParameterError, match="amplifies the reference by 10 dB"):
        compensation(m, r, fs=FS)
    kept = compensation(m, r, fs=FS, force=True)
    assert kept.check is None and "bound 0.333×" in kept.failed_check
    assert_allclose(m.simulate(kept.drive), r, rtol=0, atol=1e-12)


def test_compensate_refuses_the_keywords_it_does_not_take():
    """compensate keeps no forced drive and no fade: those are compensation's."""
    m, r = _model(b=(10.0, 5.0)), _reference()
    for name, value in (("force", True), ("fade_s", 0.1), ("rate", FS)):
        with pytest.raises(TypeError, match=rf"unexpected keyword arguments \['{name}'\]"):
            compensate(m, r, fs=FS, **{name: value})


def test_warnings_are_returned_by_the_library_and_emitted_by_compensate():
    m = ArmaxModel(a=[1.0, -1.5, 0.7], b=[0.1, 0.05], delay=2, dt=1 / FS, band_hz=(20.0, 100.0))
    r = _reference()  # most of its power at 5 and 13 Hz, below the band
    result = compensation(m, r, fs=FS)  # warnings are errors here: none is emitted
    assert len(result.warnings) == 1 and "outside the band" in result.warnings[0]
    with pytest.warns(EhssWarning, match="outside the band"):
        compensate(m, r, fs=FS)


def test_fade_brings_the_reference_to_rest():
    r = 0.005 + _reference()
    with pytest.raises(ParameterError, match="--fade"):
        compensation(_model(), r, fs=FS)
    result = compensation(_model(), r, fs=FS, fade_s=0.2)
    assert result.reference[0] == pytest.approx(0.0, abs=1e-15)
    assert result.reference[-1] == pytest.approx(0.0, abs=1e-15)


def test_iteration_step_runs_the_same_sequence():
    """corrected_drive: about the operating point and checked, as the one-shot drive."""
    from ehss.compensation import corrected_drive

    m = _model(offsets=(2.0, 1.5))
    r = 1.5 + _reference()
    first = compensation(m, r, fs=FS)

    def plant(u):  # the loop 10 % weaker than the model, about the same operating point
        return 1.5 + 0.9 * m.simulate(u - 2.0)

    nxt, step = corrected_drive(m, r, first.drive, plant(first.drive), fs=FS)
    assert nxt.offsets == (2.0, 1.5) and nxt.check is not None and step.accepted
    e0, e1 = r - plant(first.drive), r - plant(nxt.drive)
    # gain 1, exact inverse in the band: |1 − 0.9| = 0.1 of the error is left (rounding)
    assert_allclose(e1, 0.1 * e0, rtol=0, atol=1e-9 * np.max(np.abs(e0)))
    with pytest.raises(ParameterError, match=r"bound 0\.5×"):
        corrected_drive(m, r, first.drive, plant(first.drive), fs=FS,
                        checks={"max_gain": 0.5})
