"""The workflow's settings objects: each checks itself once, and the command line builds
the same objects from its flags."""

from __future__ import annotations

import argparse
import dataclasses

import numpy as np
import pytest

from ehss.cli._options import add_options, build_options
from ehss.compensation import UpdateOptions
from ehss.errors import ParameterError
from ehss.workflow import (
    Acceptance,
    Estimation,
    Evaluation,
    OrderGrid,
    Preparation,
)

KINDS = (Preparation, Estimation, Evaluation, OrderGrid, Acceptance, UpdateOptions)


@pytest.mark.parametrize("kind", KINDS)
def test_the_defaults_pass_their_own_checks_and_every_field_declares_one(kind):
    obj = kind()
    for f in dataclasses.fields(kind):
        assert callable(f.metadata["check"]), f.name
        # the check returns the value it was given back (converted, not changed)
        value = getattr(obj, f.name)
        assert f.metadata["check"](value, f.name) == value or value is None


@pytest.mark.parametrize("kind", KINDS)
def test_settings_are_frozen(kind):
    obj = kind()
    name = dataclasses.fields(kind)[0].name
    with pytest.raises(dataclasses.FrozenInstanceError):
        setattr(obj, name, getattr(obj, name))


@pytest.mark.parametrize(
    "make,exc,match",
    [
        (lambda: Preparation(validation=0.0), ParameterError,
         r"validation=0.0 must be in \(0, 1\)"),
        (lambda: Preparation(band_hz=(3.0, 1.0)), ParameterError, "lo < hi"),
        (lambda: Preparation(decimate=1.5), TypeError, "decimate=1.5 must be an integer"),
        (lambda: Estimation(init="warm"), ParameterError, "init='warm'"),
        (lambda: Evaluation(nperseg=7), ParameterError, r"nperseg=7 must be an integer in \[8"),
        (lambda: Evaluation(horizons=(1, 0)), ParameterError, "horizons"),
        (lambda: OrderGrid(na=[0]), ParameterError, "na=\\[0\\] must hold integers >= 1"),
        (lambda: OrderGrid(nb=[1.5]), TypeError, "nb"),
        (lambda: Acceptance(min_coherence=1.5), ParameterError, "min_coherence=1.5"),
        (lambda: Acceptance(min_frf_points=0), ParameterError, "min_frf_points=0"),
        (lambda: UpdateOptions(gain=2.0), ParameterError, r"gain=2.0 must be in \(0, 2\)"),
        (lambda: UpdateOptions(reidentify=1), TypeError, "reidentify=1 must be true or false"),
        (lambda: UpdateOptions(orders=(0, 1)), ParameterError, "orders\\[0\\]=0"),
        (lambda: UpdateOptions(known=[1.0]), ParameterError, "pair \\(num, den\\)"),
    ],
)
def test_a_bad_setting_is_refused_by_name(make, exc, match):
    with pytest.raises(exc, match=match):
        make()


def test_values_are_converted_once():
    grid = OrderGrid(na=range(1, 3), nb=[0, 1], nc=np.array([1]), delay=4)
    assert (grid.na, grid.nb, grid.nc, grid.delay) == ((1, 2), (0, 1), (1,), (4,))
    assert grid.size == 2 * 2 * 1 * 1
    assert OrderGrid().size == 4 * 4 * 2 * 2  # nb 0-3 and two delays when left open
    u = [0.0, 1.0] * 20
    prep = Preparation(validation=(u, u))
    assert prep.holdout is None and all(isinstance(x, np.ndarray) for x in prep.validation)
    assert Preparation().holdout == 0.3
    known = UpdateOptions(known=([1, 0.5], [1, -0.2])).known
    assert known is not None and known[0].dtype == np.float64


def _parser(*kinds: type) -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(exit_on_error=False)
    for kind in kinds:
        add_options(p, kind)
    return p


def test_no_flags_give_the_defaults():
    args = _parser(Preparation, Estimation, Evaluation, Acceptance).parse_args([])
    for kind in (Estimation, Evaluation, Acceptance):
        assert build_options(args, kind) == kind()
    prep = build_options(args, Preparation)
    assert (prep.validation, prep.band_hz, prep.detrend, prep.decimate) == (
        0.3, None, "mean", "auto")


def test_flags_build_the_object_the_library_takes():
    args = _parser(Preparation, Estimation, Evaluation, Acceptance, UpdateOptions).parse_args(
        ["--holdout", "0.25", "--band", "1", "20", "--detrend", "none", "--decimate", "4",
         "--method", "rels", "--init", "zero", "--nperseg", "64", "--frf-method", "dft",
         "--initial", "zero", "--min-coherence", "0.8", "--gain", "0.5", "--reidentify"])
    prep = build_options(args, Preparation)
    assert (prep.validation, prep.band_hz, prep.detrend, prep.decimate) == (
        0.25, (1.0, 20.0), None, 4)
    assert build_options(args, Estimation) == Estimation(method="rels", init="zero")
    assert build_options(args, Evaluation) == Evaluation(nperseg=64, frf_method="dft",
                                                         initial="zero")
    assert build_options(args, Acceptance) == Acceptance(min_coherence=0.8)
    upd = build_options(args, UpdateOptions, method="frf")
    assert (upd.gain, upd.reidentify, upd.method) == (0.5, True, "frf")


@pytest.mark.parametrize(
    "argv,match",
    [
        (["--holdout", "1.5"], "--holdout 1.5 must be in (0, 1)"),
        (["--nperseg", "4"], "--nperseg 4 must be an integer in [8, inf)"),
        (["--band", "5", "1"], "--band 5 1 must satisfy 0 <= LO < HI"),
        (["--decimate", "x"], "--decimate 'x' must be auto, none or an integer >= 1"),
        (["--min-coherence", "2"], "--min-coherence 2.0 must be in [0, 1]"),
    ],
)
def test_a_bad_flag_is_named_as_typed(argv, match):
    args = _parser(Preparation, Evaluation, Acceptance).parse_args(argv)
    with pytest.raises(ParameterError) as err:
        for kind in (Preparation, Evaluation, Acceptance):
            build_options(args, kind)
    assert str(err.value).startswith(match), str(err.value)


def test_only_the_fields_asked_for_are_offered():
    p = argparse.ArgumentParser()
    add_options(p, Evaluation, only=("initial",))
    flags = {a.option_strings[0] for a in p._actions if a.option_strings}
    assert flags == {"-h", "--initial"}
