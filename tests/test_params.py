from __future__ import annotations

import dataclasses
import math

import pytest

from ehss.errors import DataError, ParameterError
from ehss.params import (
    ActuatorParams,
    LoadParams,
    RigParams,
    SensorParams,
    TimingParams,
    ValveParams,
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
    with pytest.raises(TypeError, match="LoadParams"):
        RigParams(load=ActuatorParams())


# ----------------------------------------------------------------------- types and ranges
def test_every_numeric_field_has_a_range_and_presets_lie_inside():
    from ehss.params import RANGES

    for name in ("default", "paper"):
        p = preset(name)
        for section in dataclasses.fields(p):
            if section.name == "name":
                continue
            obj = getattr(p, section.name)
            spec = RANGES[type(obj).__name__]
            for f in dataclasses.fields(obj):
                if isinstance(f.default, bool):
                    continue
                assert f.name in spec, f"{type(obj).__name__}.{f.name} has no range"


@pytest.mark.parametrize(
    ("factory", "kwargs", "error", "match"),
    [
        (ValveParams, {"saturate": "no"}, TypeError, r"saturate='no' must be true or false"),
        (ValveParams, {"saturate": 0}, TypeError, "true or false"),
        (SensorParams, {"quantize": None}, TypeError, "true or false"),
        (SensorParams, {"adc_bits": 16.0}, TypeError, "must be an integer"),
        (SensorParams, {"adc_bits": 64}, ParameterError, r"\[2, 32\]"),
        (LoadParams, {"mass_kg": "250"}, TypeError, "real number"),
        (LoadParams, {"mass_kg": 1e9}, ParameterError, r"mass_kg=1000000000.0 must be in "
                                                       r"\[0.001, 1e\+07\] kg"),
        (LoadParams, {"mass_kg": 10**400}, ParameterError, "too large for a float"),
        (TimingParams, {"internal_rate_hz": 1e9}, ParameterError, r"\[1, 1e\+06\] Hz"),
        (TimingParams, {"control_rate_hz": 10.0, "internal_rate_hz": 100_000.0},
         ParameterError, "at most 1000 plant steps"),
        (TimingParams, {"control_rate_hz": 0.5, "internal_rate_hz": 1.0}, ParameterError,
         "control_rate_hz"),
        (SensorParams, {"lvdt_noise_m": 1.0}, ParameterError, "must not exceed lvdt_range_m"),
        (ValveParams, {"null_bias": 0.5}, ParameterError, r"\(-0.5, 0.5\)"),
        (ValveParams, {"deadband": 0.5}, ParameterError, r"\[0, 0.5\)"),
    ],
)
def test_wrong_types_and_absurd_values(factory, kwargs, error, match):
    with pytest.raises(error, match=match):
        factory(**kwargs)


def test_ints_given_for_reals_are_stored_as_floats():
    m = LoadParams(mass_kg=300).mass_kg
    assert type(m) is float and m == 300.0


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ('[valve]\nsaturate = "no"\n', r"p.toml: valve.saturate='no' must be true or false"),
        ("[timing]\ninternal_rate_hz = 1e9\n", r"timing.internal_rate_hz=.* \[1, 1e\+06\] Hz"),
        ('[load]\nmass_kg = "250"\n', "load.mass_kg='250' must be a real number"),
        ("[sensors]\nadc_bits = 16.5\n", "sensors.adc_bits=16.5 must be an integer"),
        ("preset = 3\n", "preset=3 must be the name of a preset"),
        ("load = 3\n", r"section \[load\] must be a table"),
        ("name = 3\n", "name=3 must be a string"),
        ("[timing]\ncontrol_rate_hz = 10\ninternal_rate_hz = 100000\n",
         r"\[timing\] internal_rate_hz=100000.0 is 10000 times"),
        ("[load\nmass_kg = 1\n", "is not valid TOML"),
        ("x = " + "[" * 5000 + "]" * 5000 + "\n", "nested too deeply|not valid TOML"),
    ],
)
def test_bad_parameter_files_name_file_and_entry(tmp_path, text, match):
    f = tmp_path / "p.toml"
    f.write_text(text, encoding="utf-8")
    with pytest.raises(ParameterError, match=match):
        load_params(f)


def test_non_utf8_and_folder_parameter_files(tmp_path):
    f = tmp_path / "p.toml"
    f.write_bytes(b"[load]\nmass_kg = 250 # \xe9\xff\n")
    with pytest.raises(ParameterError, match="not UTF-8"):
        load_params(f)
    with pytest.raises(ParameterError, match="is a folder"):
        load_params(tmp_path)


def test_save_params_is_atomic_and_refuses_bad_places(tmp_path):
    p = preset()
    with pytest.raises(DataError, match="does not exist"):
        save_params(p, tmp_path / "missing" / "p.toml")
    with pytest.raises(DataError, match="is a folder"):
        save_params(p, tmp_path)
    ro = tmp_path / "ro.toml"
    ro.write_text("keep\n")
    ro.chmod(0o444)
    with pytest.raises(DataError, match="read-only"):
        save_params(p, ro)
    assert ro.read_text() == "keep\n"
    assert sorted(x.name for x in tmp_path.iterdir()) == ["ro.toml"]  # no temporary left
