"""ehss batch on every kind of record, and on bad input: each failure one row or one
line, nothing lost. Run in this process (``workers=0``): the cluster tests cover Dask."""

from __future__ import annotations

import json

import h5py
import numpy as np
import polars as pl
import pytest
import scipy.signal

from ehss.campaign import BatchSettings, batch, load_manifest
from ehss.errors import ParameterError

from .conftest import N_SAMPLES, A, B, make_archive, run_cli


def loop_record(rng, n=N_SAMPLES):
    u = rng.standard_normal(n)
    return u, scipy.signal.lfilter(B, A, u) + 0.01 * rng.standard_normal(n)


def test_bad_records_are_rows_and_the_rest_go_on(tmp_path):
    manifest = make_archive(tmp_path, n=4)
    (tmp_path / "records" / "garbled.csv").write_text("t,ref1,fb1\n0,1\n")
    lacking = tmp_path / "records" / "lacking.csv"
    lacking.write_text("t,ref1,other\n" + "".join(f"{i / 1000},{i % 7},{i % 3}\n"
                                                   for i in range(400)))
    frame = batch([str(tmp_path / "records" / "*.csv"), str(tmp_path / "missing.csv")],
                  tmp_path / "out", manifest=manifest, workers=0)
    by = {r["record"].rsplit("/", 1)[-1]: r for r in frame.iter_rows(named=True)}
    assert len(by) == 7 and frame.height == 7  # every record has its row
    assert [by[f"run{i:03d}.csv"]["status"] for i in range(4)] == ["ok"] * 4
    assert "no such file" in by["missing.csv"]["error"]
    assert "garbled.csv" in by["garbled.csv"]["error"]
    assert "fb1" in by["lacking.csv"]["error"] and "other" in by["lacking.csv"]["error"]
    for r in frame.filter(pl.col("status") == "error").iter_rows(named=True):
        assert "\n" not in r["error"]
    html = (tmp_path / "out" / "summary.html").read_text()
    assert "Failures (3)" in html and "<script" not in html and "http" not in html


def test_identifies_the_known_loop(tmp_path):
    frame = batch(None, tmp_path / "out", manifest=make_archive(tmp_path, n=3), workers=0,
                  summary=False)
    a = np.array(frame["a"].to_list())
    # noise 1 % of the output on 280 estimation samples: coefficients within 0.02
    np.testing.assert_allclose(a, np.tile(A, (3, 1)), atol=0.02)
    assert (frame["fit_pct"] > 90).all()  # the acceptance's fit; 1 % noise allows ~99
    model = json.loads((tmp_path / "out" / frame["model_file"][0]).read_text())
    assert model["meta"]["channel"] == "1"


def test_hdf5_groups_live_recordings_and_parquet(tmp_path):
    from ehss.io import write_table

    rng = np.random.default_rng(1)
    t = np.arange(N_SAMPLES) / 1000.0
    with h5py.File(tmp_path / "day.h5", "w") as h:
        for g in ("run1", "run2"):
            u, y = loop_record(rng)
            grp = h.create_group(g)
            grp["t"], grp["ref1"], grp["fb1"] = t, u, y
            grp.attrs["recorded_at"] = f"2026-03-0{g[-1]}T09:00:00+00:00"
    u1, y1 = loop_record(rng)
    u2, y2 = loop_record(rng)
    with h5py.File(tmp_path / "live.h5", "w") as h:  # the layout ehss live writes
        h.attrs["fields"] = json.dumps(["t", "ref1", "fb1", "ref2", "fb2"])
        h.attrs["fs"] = 1000.0
        h["samples"] = np.column_stack([t, u1, y1, u2, y2])
    u, y = loop_record(rng)
    write_table(tmp_path / "p.parquet", {"t": t, "ref1": u, "fb1": y}, {})
    settings = BatchSettings(orders=(2, 2, 0, 1), method="arx", decimate=None)
    frame = batch([str(tmp_path / "*.h5"), str(tmp_path / "p.parquet")], tmp_path / "out",
                  settings=settings, workers=0, summary=False)
    assert frame["status"].to_list() == ["ok"] * 5, frame["error"].to_list()
    names = [(r.rsplit("/", 1)[-1], c) for r, c in zip(frame["record"], frame["channel"],
                                                        strict=True)]
    assert names == [("day.h5::run1", "1"), ("day.h5::run2", "1"), ("live.h5", "1"),
                     ("live.h5", "2"), ("p.parquet", "1")]
    assert frame["time_source"][0] == "metadata 'recorded_at'"
    assert frame["time_source"][2] == "file modification time"
    np.testing.assert_allclose(np.array(frame["a"].to_list()), np.tile(A, (5, 1)),
                               atol=0.02)


def test_manifest_mistakes_are_one_line(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("[workflow]\norder = [2, 2, 0, 1]\n")
    with pytest.raises(ParameterError, match=r"unknown key\(s\) \['order'\] in \[workflow\]"):
        load_manifest(bad)
    res = run_cli("batch", "x.csv", "--manifest", str(bad), "--out", str(tmp_path / "o"))
    assert res.returncode == 2
    assert res.stderr.strip().splitlines() == [
        f"ehss batch: error: {bad}: unknown key(s) ['order'] in [workflow]; accepted: "
        "band_hz, decimate, detrend, holdout, method, orders"]


def test_a_campaign_resumes_only_with_its_own_settings(tmp_path):
    manifest = make_archive(tmp_path, n=2)
    batch(None, tmp_path / "out", manifest=manifest, workers=0, summary=False)
    other = load_manifest(manifest, orders=(3, 2, 0, 1))
    with pytest.raises(ParameterError, match=r"other settings \(orders: \[2, 2, 0, 1\] "
                                             r"then, \[3, 2, 0, 1\] now\)"):
        batch(None, tmp_path / "out", settings=other, workers=0)
