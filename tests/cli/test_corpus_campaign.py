"""Hostile input to ``ehss batch`` and ``ehss montecarlo``, run as users run them: a
record named that does not exist, a manifest or a specification whose values are not
of their kind, cluster options that mean nothing, the campaign folder onto an input.
Each is one line on stderr and exit 2, before the campaign folder is made.
"""

from __future__ import annotations

import numpy as np
import pytest

from ehss.io import write_table


@pytest.fixture
def folder(tmp_path):
    t = np.arange(1000) / 500.0
    write_table(tmp_path / "good.csv", {"t": t, "ref1": np.sin(20 * t),
                                        "fb1": np.cos(20 * t)}, metadata={})
    return tmp_path


NOTHING = "*.nothing"  # a glob that matches no record: the run stops before any work

BATCH = {
    "a named record missing": (["none.csv"], ("none.csv", "no such file")),
    "a glob matching nothing": ([NOTHING], ("*.nothing",)),
    "out onto the record": (["good.csv", "--out", "good.csv"], ("good.csv",)),
    "out onto its sidecar": (["good.csv", "--out", "good.json"], ("good.json",)),
    "workers negative": ([NOTHING, "--workers", "-1"], ("--workers",)),
    "connect timeout zero": ([NOTHING, "--connect-timeout", "0"], ("--connect-timeout",)),
    "scheduler of no scheme Dask knows": ([NOTHING, "--scheduler", "http://x:1"],
                                          ("--scheduler", "http://x:1")),
    "scheduler without a port": ([NOTHING, "--scheduler", "tcp://"], ("--scheduler",)),
    "orders zero": ([NOTHING, "--orders", "0", "0", "0", "0"], ("na",)),
    "orders text": ([NOTHING, "--orders", "a", "b", "c", "d"], ("--orders",)),
    "band reversed": ([NOTHING, "--band", "10", "5"], ("--band",)),
    "band nan": ([NOTHING, "--band", "nan", "5"], ("--band",)),
    "fs zero": ([NOTHING, "--fs", "0"], ("fs",)),
    "manifest missing": ([NOTHING, "--manifest", "none.toml"], ("none.toml",)),
}


@pytest.mark.parametrize("case", list(BATCH))
def test_batch_refuses(folder, refused, case):
    argv, words = BATCH[case]
    out = [] if "--out" in argv else ["--out", "campaign"]
    workers = [] if "--workers" in argv else ["--workers", "0"]
    refused(["batch", *argv, *out, *workers, "--quiet"], folder, *words)


MANIFESTS = {
    "not toml": ("not = [toml", ("m.toml",)),
    "unknown key": ("wings = 2", ("wings",)),
    "fs text": ('fs = "fast"', ("m.toml", "fs")),
    "seed text": ('seed = "x"', ("m.toml", "seed")),
    "records a number": ("records = 5", ("m.toml", "records")),
    "records of numbers": ("records = [1, 2]", ("m.toml", "records")),
    "channels a number": ("channels = 5", ("m.toml", "channels")),
    "channel without columns": ('[[channels]]\nname = "1"', ("m.toml", "channels")),
    "time column a number": ("time_column = 5", ("time_column",)),
    "orders text": ('[workflow]\norders = "x"', ("orders",)),
    "orders three": ("[workflow]\norders = [4, 3, 4]", ("orders",)),
    "band text": ('[workflow]\nband_hz = ["a", "b"]', ("m.toml", "band_hz")),
    "band reversed": ("[workflow]\nband_hz = [50, 5]", ("band_hz",)),
    "holdout text": ('[workflow]\nholdout = "x"', ("m.toml", "holdout")),
    "detrend unknown": ('[workflow]\ndetrend = "cubic"', ("detrend",)),
    "decimate zero": ("[workflow]\ndecimate = 0", ("decimate",)),
    "method a number": ("[workflow]\nmethod = 3", ("method",)),
    "acceptance text": ('[acceptance]\nmin_fit_pct = "x"', ("m.toml", "min_fit_pct")),
    "outliers text": ('[outliers]\nalpha = "x"', ("m.toml", "alpha")),
}


@pytest.mark.parametrize("case", list(MANIFESTS))
def test_batch_refuses_a_manifest_that_means_nothing(folder, refused, case):
    text, words = MANIFESTS[case]
    (folder / "m.toml").write_text(text + "\n")
    refused(["batch", NOTHING, "--manifest", "m.toml", "--out", "campaign", "--workers",
             "0", "--quiet"], folder, *words)


def _spec(parameter: str) -> str:
    return f'samples = 4\nduration_s = 10.0\n[parameters."load.mass_kg"]\n{parameter}\n'


SPECS = {
    "missing": (None, ("none.toml",)),
    "not toml": ("not = [toml", ("spec.toml",)),
    "no parameters": ("samples = 4", ("parameters",)),
    "unknown parameter": ('samples = 4\n[parameters."load.wings"]\ndistribution = '
                          '"uniform"\nrel = 0.2', ("load.wings",)),
    "unknown distribution": (_spec('distribution = "cauchy"\nrel = 0.2'), ("cauchy",)),
    "spread text": (_spec('distribution = "normal"\nrel_std = "x"'), ("rel_std",)),
    "spread a boolean": (_spec('distribution = "normal"\nrel_std = true'), ("rel_std",)),
    "bounds reversed": (_spec('distribution = "uniform"\nlow = 5\nhigh = 1'), ("low",)),
    "too short a test": ('samples = 4\nduration_s = 1.0\n[parameters."load.mass_kg"]\n'
                         'distribution = "uniform"\nrel = 0.2', ("duration_s",)),
}


@pytest.mark.parametrize("case", list(SPECS))
def test_montecarlo_refuses_a_specification_that_means_nothing(folder, refused, case):
    text, words = SPECS[case]
    name = "none.toml" if text is None else "spec.toml"
    if text is not None:
        (folder / name).write_text(text + "\n")
    refused(["montecarlo", name, "--out", "mc", "--workers", "0", "--quiet"], folder, *words)


@pytest.mark.parametrize(("extra", "words"), [
    (["--workers", "-1"], ("--workers",)),
    (["--scheduler", "http://x:1"], ("--scheduler",)),
    (["--connect-timeout", "-1"], ("--connect-timeout",)),
    (["--samples", "0"], ("samples",)),
    (["--out", "spec.toml"], ("spec.toml",)),
])
def test_montecarlo_refuses_options_that_mean_nothing(folder, refused, extra, words):
    (folder / "spec.toml").write_text(_spec('distribution = "uniform"\nrel = 0.2'))
    out = [] if "--out" in extra else ["--out", "mc"]
    refused(["montecarlo", "spec.toml", *out, *extra, "--quiet"], folder, *words)
