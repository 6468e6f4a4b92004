from __future__ import annotations

import dataclasses
import math

import pytest

from ehss.errors import ParameterError
from ehss.params import (
    ActuatorParams,
    LoadParams,
    RigParams,
    TimingParams,
    load_params,
    params_to_dict,
    preset,
    save_params,
)


def test_default_gives_paper_oil_column():
    p = preset("default")
    # PAPER.md §5 / Table 1: ωh = 32 Hz, ζh = 0.35 (acceptance: ±1 Hz, ±0.02).
    assert abs(p.hydraulic_freq_hz - 32.0) <= 1.0
    assert abs(p.hydraulic_damping - 0.35) <= 0.02


def test_paper_preset_is_inconsistent_as_documented():
    p = preset("paper")
    # Table 1 taken literally: ωh ≈ 7.2 Hz and ζh ≈ 0.12 (PAPER.md §5).
    assert p.hydraulic_freq_hz == pytest.approx(7.17, abs=0.05)
    assert p.hydraulic_damping == pytest.approx(0.12, abs=0.005)
    assert p.flow_gain_m3_s_v == pytest.approx(0.00145, rel=1e-12)
    assert p.acceleration.kdf_v_per_m == 24.5


def test_derived_identities():
    p = preset("default")
    a, m = p.actuator, p.load.mass_kg
    # Kh = mt ωh² (eq 8, the paper's "mt ωh" is a typo).
    assert p.hydraulic_stiffness_n_m == pytest.approx(m * p.hydraulic_omega_rad_s**2, rel=1e-12)
    # ω0 = ωh √(1 + K/Kh).
    k = p.load.specimen_stiffness_n_m
    assert p.force_omega0_rad_s == pytest.approx(
        math.sqrt((p.hydraulic_stiffness_n_m + k) / m), rel=1e-12
    )
    # Kq at null from the rating: 38 L/min · √(21/7) ≈ 65.8 L/min per full spool.
    assert p.flow_gain_m3_s * 60e3 == pytest.approx(38.0 * math.sqrt(3.0), rel=1e-12)
    assert p.velocity_gain_m_s == pytest.approx(p.flow_gain_m3_s / a.piston_area_m2)


@pytest.mark.parametrize(
    ("factory", "kwargs", "match"),
    [
        (LoadParams, {"mass_kg": -1.0}, "mass_kg"),
        (ActuatorParams, {"oil_density_kg_m3": 0.0}, "oil_density"),
        (ActuatorParams, {"bulk_modulus_pa": float("nan")}, "finite"),
        (TimingParams, {"internal_rate_hz": 10_500.0}, "integer multiple"),
        (TimingParams, {"delay_samples": -1}, "delay_samples"),
        (ActuatorParams, {"stroke_m": 0.3}, "chamber would empty"),
    ],
)
def test_bad_parameters_are_refused(factory, kwargs, match):
    with pytest.raises(ParameterError, match=match):
        factory(**kwargs)


def test_toml_round_trip(tmp_path):
    p = dataclasses.replace(preset("paper"), load=LoadParams(mass_kg=123.0))
    path = save_params(p, tmp_path / "rig.toml")
    q = load_params(path)
    assert q == p
    assert params_to_dict(q) == params_to_dict(p)


def test_partial_toml_and_unknown_key(tmp_path):
    f = tmp_path / "rig.toml"
    f.write_text("[load]\nmass_kg = 300\n")
    assert load_params(f).load.mass_kg == 300.0
    f.write_text("[load]\nmas_kg = 300\n")
    with pytest.raises(ParameterError, match="unknown parameter load.mas_kg"):
        load_params(f)
    with pytest.raises(ParameterError, match="does not exist"):
        load_params(tmp_path / "none.toml")


def test_rig_params_type_checked():
    with pytest.raises(ParameterError, match="LoadParams"):
        RigParams(load=ActuatorParams())
