"""Table and JSON writers: exact values in every format, same metadata, nothing lost."""

from __future__ import annotations

import csv
import json
import math
import os
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.testing import assert_array_equal

from ehss.cli import main
from ehss.errors import DataError
from ehss.io import read_columns, read_metadata, to_jsonable, write_csv, write_json, write_table


def test_write_json_converts_numpy(tmp_path):
    obj = {
        "a": np.array([1.0, 0.1 + 0.2]),
        "n": np.int64(3),
        "ok": np.bool_(True),
        "x": np.float32(0.5),
        "bad": [math.nan, -math.inf],
        "path": Path("run.csv"),
        "nested": ({"k": (1, 2)},),
    }
    path = write_json(tmp_path / "out.json", obj)
    text = path.read_text()
    assert text.startswith("{\n  ")  # indent 2
    back = json.loads(text)
    assert back["a"] == [1.0, 0.1 + 0.2]  # full precision through repr
    assert back["n"] == 3 and back["ok"] is True and back["x"] == 0.5
    assert back["bad"] == [None, None]  # JSON has no NaN or infinity
    assert back["path"] == "run.csv" and back["nested"] == [{"k": [1, 2]}]


def test_write_json_failure_leaves_old_file(tmp_path):
    path = tmp_path / "out.json"
    path.write_text("old")
    with pytest.raises(TypeError, match="complex"):
        write_json(path, {"z": 1j})
    assert path.read_text() == "old"
    assert [p.name for p in tmp_path.iterdir()] == ["out.json"]


def test_to_jsonable_rejects_objects():
    with pytest.raises(TypeError, match="object"):
        to_jsonable({"o": object()})


def test_write_csv_header_comment_and_values(tmp_path):
    path = write_csv(tmp_path / "c.csv", {"x": [1, 2], "y": np.array([0.1, 1e-300])},
                     header_comment="made by a test\nsecond line")
    lines = path.read_text().splitlines()
    assert lines[:3] == ["# made by a test", "# second line", "x,y"]
    assert lines[3:] == ["1.0,0.1", "2.0,1e-300"]
    assert read_columns(path)["y"][1] == 1e-300


@pytest.mark.parametrize(
    "columns,match",
    [
        ({}, "no columns"),
        ({"a": [1, 2], "b": [1]}, "unequal lengths"),
        ({"a,b": [1]}, "column name"),
        ({"a": [[1, 2]]}, "expected 1-D"),
        ({"a": ["x"]}, "expected real"),
    ],
)
def test_write_csv_rejects(tmp_path, columns, match):
    with pytest.raises(DataError, match=match):
        write_csv(tmp_path / "c.csv", columns)
    assert not (tmp_path / "c.csv").exists()


def test_write_to_missing_folder(tmp_path):
    with pytest.raises(DataError, match="does not exist"):
        write_csv(tmp_path / "no" / "c.csv", {"a": [1.0]})


# ---- tables in every format --------------------------------------------------------------

FORMATS = ("csv", "parquet", "h5", "hdf5", "npz", "mat")


def _hard_doubles(rng, n=4000):
    """Random bit patterns (every exponent, subnormals included) and the edge cases of
    decimal text: the extremes, the smallest subnormal, signed zero, 0.1, 1/3, 2**53 + 1."""
    bits = rng.integers(0, 2**64 - 1, n, dtype=np.uint64, endpoint=True).view(np.float64)
    subnormal = rng.integers(1, 2**52, 200, dtype=np.uint64).view(np.float64)
    edges = np.array([5e-324, -5e-324, 2.2250738585072014e-308, 2.225073858507201e-308,
                      1.7976931348623157e308, -1.7976931348623157e308, -0.0, 0.0, 0.1,
                      1 / 3, 2.0**53 + 2, 1e22, 1e23, 1e-300, 123456789012345678.0])
    x = np.concatenate([bits[np.isfinite(bits)], subnormal, -subnormal, edges])
    return x[: (x.size // 3) * 3]


@pytest.mark.parametrize("ext", FORMATS)
def test_table_round_trip_is_bit_exact(tmp_path, rng, ext):
    x = _hard_doubles(rng)
    cols = {"t": np.arange(x.size // 3) * 1e-3, "u": x[0::3], "y_m": x[1::3],
            "flag": x[2::3]}
    meta = {"fs_hz": 1000.0, "units": {"u": "V"}, "seed": 7, "note": "ünïcode"}
    written = write_table(tmp_path / f"rec.{ext}", cols, meta)
    assert written[0] == tmp_path / f"rec.{ext}"
    table = read_columns(tmp_path / f"rec.{ext}")
    # (the HDF5 reader lists datasets by name, the others in the written order)
    assert sorted(table) == sorted(cols) and table.time_column == "t"
    for name, values in cols.items():
        # the same bits: -0.0, subnormals and the extremes survive every format
        assert_array_equal(table[name].view(np.int64), values.view(np.int64), name)
    assert read_metadata(tmp_path / f"rec.{ext}") == meta
    expected = {f"rec.{ext}", "rec.json"} if ext == "csv" else {f"rec.{ext}"}
    assert {p.name for p in tmp_path.iterdir()} == expected


# At least 2 samples: MATLAB has no 1-vector distinct from a scalar (a 1x1 double), and
# the reader skips scalars (e.g. a stored sample rate) when it looks for columns.
@settings(max_examples=60, deadline=None)
@given(values=st.lists(st.floats(allow_nan=False, allow_infinity=False), min_size=2,
                       max_size=40),
       ext=st.sampled_from(FORMATS))
def test_any_finite_doubles_round_trip(values, ext):
    x = np.array(values, dtype=np.float64)
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / f"x.{ext}"
        write_table(path, {"x": x}, {"n": x.size})
        assert_array_equal(read_columns(path)["x"].view(np.int64), x.view(np.int64))


def test_csv_text_reads_back_with_pythons_own_parser(tmp_path, rng):
    """An independent reader (csv module and float()) gets the same bits."""
    x = _hard_doubles(rng)
    path = write_csv(tmp_path / "x.csv", {"x": x})
    with open(path, newline="") as fh:
        rows = list(csv.reader(fh))
    assert rows[0] == ["x"]
    back = np.array([float(r[0]) for r in rows[1:]])
    assert_array_equal(back.view(np.int64), x.view(np.int64))


def test_csv_sidecar_is_marked_as_the_tables(tmp_path):
    # metadata copied from another table's sidecar cannot carry its marker along
    write_table(tmp_path / "a.csv", {"t": [0.0, 1.0]}, {"k": 1, "ehss_sidecar_of": "b.csv"})
    doc = json.loads((tmp_path / "a.json").read_text())
    assert doc == {"ehss_sidecar_of": "a.csv", "k": 1}
    # a second write replaces its own sidecar
    write_table(tmp_path / "a.csv", {"t": [0.0, 2.0]}, {"k": 2})
    assert json.loads((tmp_path / "a.json").read_text())["k"] == 2


@pytest.mark.parametrize(
    ("name", "columns", "match"),
    [
        ("x.json", {"t": [1.0]}, "a .json name is kept"),
        ("x.JSON", {"t": [1.0]}, "a .json name is kept"),
        ("x.xlsx", {"t": [1.0]}, "unknown ending '.xlsx'"),
        ("x", {"t": [1.0]}, "unknown ending '\\(none\\)'"),
        ("x.mat", {"1st": [1.0]}, "not a MATLAB variable name"),
        ("x.mat", {"a-b": [1.0]}, "not a MATLAB variable name"),
        ("x.h5", {"a/b": [1.0]}, "cannot be stored in hdf5"),
        ("x.npz", {"ehss_metadata": [1.0]}, "holds the metadata"),
        ("x.parquet", {"a": [1.0], "b": [1.0, 2.0]}, "unequal lengths"),
        ("x.csv", {}, "no columns"),
    ],
)
def test_write_table_rejects(tmp_path, name, columns, match):
    with pytest.raises(DataError, match=match):
        write_table(tmp_path / name, columns, {})
    assert list(tmp_path.iterdir()) == []


def test_write_table_keeps_a_users_json_beside_the_table(tmp_path):
    (tmp_path / "run.json").write_text('{"mine": true}')
    with pytest.raises(DataError, match="not the JSON sidecar ehss wrote for"):
        write_table(tmp_path / "run.csv", {"t": [1.0]}, {})
    assert (tmp_path / "run.json").read_text() == '{"mine": true}'
    assert [p.name for p in tmp_path.iterdir()] == ["run.json"]


def test_write_table_failure_writes_nothing(tmp_path):
    (tmp_path / "run.parquet").write_bytes(b"old")
    with pytest.raises(TypeError, match="complex"):
        write_table(tmp_path / "run.parquet", {"t": [1.0]}, {"z": 1j})
    assert (tmp_path / "run.parquet").read_bytes() == b"old"
    assert [p.name for p in tmp_path.iterdir()] == ["run.parquet"]


@pytest.mark.parametrize(
    ("make", "match"),
    [
        (lambda p: p.write_bytes(b"PAR1 not really"), "not a readable Parquet file"),
        (lambda p: write_table(p, {"t": [0.0, 1.0], "u": [1.0, 2.0]}, {}), "no column 'y'"),
    ],
)
def test_read_parquet_errors_name_the_file(tmp_path, make, match):
    path = tmp_path / "r.parquet"
    make(path)
    with pytest.raises(DataError, match=match) as info:
        read_columns(path, ["u", "y"])
    assert "r.parquet" in str(info.value) and "\n" not in str(info.value)


@pytest.mark.parametrize(
    "kind", ["symlink", "fifo", "read-only"],
)
def test_atomic_write_never_replaces_what_a_rename_would_destroy(tmp_path, kind):
    target = tmp_path / "target.csv"
    target.write_text("keep\n")
    path = tmp_path / "out.csv"
    if kind == "symlink":
        os.symlink(target, path)
    elif kind == "fifo":
        os.mkfifo(path)
    else:
        path.write_text("keep\n")
        os.chmod(path, 0o444)
    with pytest.raises(DataError, match="cannot write"):
        write_csv(path, {"t": [1.0]})
    assert target.read_text() == "keep\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.csv", "target.csv"]


# ---- the command line reads back every format exactly --------------------------------------


@pytest.fixture(scope="module")
def simulated(tmp_path_factory):
    """One simulated position-loop test, written by ``ehss simulate`` in every format."""
    folder = tmp_path_factory.mktemp("formats")
    for ext in FORMATS:
        code = main(["simulate", "--loop", "position", "--signal", "random", "--duration",
                     "4", "--seed", "5", "--out", str(folder / f"run.{ext}")])
        assert code == 0
    return folder


@pytest.mark.parametrize("ext", FORMATS[1:])
def test_simulate_records_are_identical_in_every_format(simulated, ext):
    csv_table = read_columns(simulated / "run.csv")
    table = read_columns(simulated / f"run.{ext}")
    assert sorted(table) == sorted(csv_table)
    for name in csv_table:
        assert_array_equal(table[name].view(np.int64), csv_table[name].view(np.int64))
    meta_csv = read_metadata(simulated / "run.csv")
    meta = read_metadata(simulated / f"run.{ext}")
    assert meta.pop("created") and meta_csv.pop("created")  # run times differ
    assert meta == meta_csv


@pytest.mark.parametrize("ext", FORMATS[1:])
def test_identify_and_frf_give_identical_results_from_every_format(simulated, tmp_path, ext):
    def results(src: Path, tag: str):
        model = tmp_path / f"{tag}_model.json"
        frf = tmp_path / f"{tag}_frf.csv"
        assert main(["identify", str(src), "--input", "reference", "--output", "output",
                     "--na", "3", "--nb", "2", "--nc", "2", "--out", str(model)]) == 0
        assert main(["frf", str(src), "--input", "reference", "--output", "output",
                     "--out", str(frf)]) == 0
        doc = json.loads(model.read_text())
        doc["provenance"].pop("input_file")
        doc["provenance"].pop("versions")
        return doc, frf.read_bytes()

    model_csv, frf_csv = results(simulated / "run.csv", "csv")
    model_bin, frf_bin = results(simulated / f"run.{ext}", ext)
    assert model_bin == model_csv  # every coefficient to the last bit (JSON keeps repr)
    assert frf_bin == frf_csv
