"""Reading columns from every supported format, and every way a file can be bad."""

from __future__ import annotations

import h5py
import numpy as np
import pytest
import scipy.io
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.testing import assert_array_equal

from ehss.errors import DataError
from ehss.io import Table, read_columns, sample_rate, write_csv


@pytest.fixture
def record(rng):
    n = 257
    return {
        "t": np.arange(n) / 1000.0,
        "u": rng.standard_normal(n),
        "y": rng.standard_normal(n) * 1e-3,
    }


def _write_mat73(path, columns):
    """A MATLAB v7.3 file as MATLAB writes it: 512-byte user block, column vectors
    stored transposed (N-by-1 in MATLAB is (1, N) in HDF5), MATLAB_class attributes."""
    with h5py.File(path, "w", userblock_size=512) as fh:
        for name, values in columns.items():
            ds = fh.create_dataset(name, data=np.asarray(values)[None, :])
            ds.attrs["MATLAB_class"] = np.bytes_("double")
        fh.create_dataset("label", data=np.array([[104], [105]], dtype=np.uint16))
        fh["label"].attrs["MATLAB_class"] = np.bytes_("char")
    with open(path, "r+b") as fh:
        head = b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: Mon Jan  1 00:00:00 2024"
        fh.write(head.ljust(116, b" ") + b"\x00" * 8 + b"\x00\x02" + b"IM")


# ---------------------------------------------------------------------------- round trips


def test_csv_round_trip_is_exact(tmp_path, record):
    path = tmp_path / "run.csv"
    write_csv(path, record, header_comment="rig A\nposition loop")
    table = read_columns(path, ["u", "y"])
    assert isinstance(table, Table)
    assert list(table) == ["t", "u", "y"]  # time column is read along
    assert table.time_column == "t"
    for name in record:
        assert_array_equal(table[name], record[name])  # repr round trip is exact
    assert table.n_rows == 257
    assert sample_rate(table) == pytest.approx(1000.0, rel=1e-12)


@pytest.mark.parametrize("sep", [";", "\t", " ", "   "])
def test_csv_delimiters_are_sniffed(tmp_path, sep):
    path = tmp_path / "run.txt"
    path.write_text(f"t{sep}u{sep}y\n0{sep}1.5{sep}-2\n0.5{sep}2.5{sep}3e-3\n")
    table = read_columns(path, ["y"])
    assert_array_equal(table["y"], [-2.0, 3e-3])
    assert_array_equal(table["t"], [0.0, 0.5])


def test_csv_quoted_header_and_bom(tmp_path):
    path = tmp_path / "excel.csv"
    path.write_bytes('\ufeff"time","drive"\r\n0,1\r\n1,2\r\n'.encode())
    table = read_columns(path, time_column="time")
    assert table.time_column == "time"
    assert_array_equal(table["drive"], [1.0, 2.0])


def test_mat_v5_round_trip(tmp_path, record):
    path = tmp_path / "run.mat"
    # MATLAB keeps vectors as 2-D: columns N-by-1 and rows 1-by-N must both read.
    scipy.io.savemat(path, {"t": record["t"][:, None], "u": record["u"], "y": record["y"]})
    table = read_columns(path, ["u", "y"])
    for name in record:
        assert_array_equal(table[name], record[name])


def test_mat_v5_struct_fields_by_path(tmp_path, record):
    path = tmp_path / "runs.mat"
    scipy.io.savemat(path, {"run1": {"u": record["u"], "y": record["y"]}})
    table = read_columns(path, ["run1/u", "run1/y"])
    assert_array_equal(table["run1/y"], record["y"])
    assert table.time_column is None


def test_mat_v73_round_trip(tmp_path, record):
    path = tmp_path / "run73.mat"
    _write_mat73(path, record)
    table = read_columns(path, ["u", "y"])
    for name in record:
        assert_array_equal(table[name], record[name])
    assert sorted(read_columns(path)) == ["t", "u", "y"]  # the char array is skipped


def test_hdf5_nested_paths(tmp_path, record):
    path = tmp_path / "runs.h5"
    with h5py.File(path, "w") as fh:
        grp = fh.create_group("run1")
        for name, values in record.items():
            grp.create_dataset(name, data=values)
    table = read_columns(path, ["run1/u", "run1/y"], time_column="run1/t")
    assert table.time_column == "run1/t"
    assert_array_equal(table["run1/u"], record["u"])
    assert sample_rate(table) == pytest.approx(1000.0, rel=1e-12)


def test_npz_round_trip(tmp_path, record):
    path = tmp_path / "run.npz"
    np.savez(path, **record)
    table = read_columns(path, ["u", "y"])
    for name in record:
        assert_array_equal(table[name], record[name])
    assert table["u"].dtype == np.float64 and table["u"].flags.c_contiguous


@settings(max_examples=25, deadline=None)
@given(st.lists(st.floats(allow_nan=False, allow_infinity=False, width=64), min_size=1,
                max_size=40))
def test_csv_round_trip_any_float(tmp_path_factory, values):
    path = tmp_path_factory.mktemp("rt") / "x.csv"
    write_csv(path, {"x": values})
    assert_array_equal(read_columns(path, ["x"])["x"], np.asarray(values))


# ------------------------------------------------------------------------------ bad input


def test_missing_file(tmp_path):
    with pytest.raises(DataError, match=r"nope\.csv'.*no such file"):
        read_columns(tmp_path / "nope.csv", ["u"])


@pytest.mark.parametrize("suffix", [".csv", ".mat", ".h5", ".npz"])
def test_garbled_file(tmp_path, suffix):
    path = tmp_path / f"junk{suffix}"
    path.write_bytes(bytes(range(256)) * 8)
    with pytest.raises(DataError, match=r"junk"):
        read_columns(path, ["u"])


def test_unknown_suffix(tmp_path):
    path = tmp_path / "run.xlsx"
    path.write_text("x")
    with pytest.raises(DataError, match=r"unknown file type '\.xlsx'"):
        read_columns(path, ["u"])


@pytest.mark.parametrize("suffix", [".csv", ".npz", ".h5"])
def test_unknown_column_lists_available(tmp_path, record, suffix):
    path = tmp_path / f"run{suffix}"
    if suffix == ".csv":
        write_csv(path, record)
    elif suffix == ".npz":
        np.savez(path, **record)
    else:
        with h5py.File(path, "w") as fh:
            for k, v in record.items():
                fh[k] = v
    with pytest.raises(DataError, match=r"no column 'x'; available: 't', 'u', 'y'"):
        read_columns(path, ["u", "x"])


def test_non_numeric_cell_names_row_and_column(tmp_path):
    path = tmp_path / "run.csv"
    path.write_text("t,u,y\n0,1,2\n0.001,1,2\n0.002,abc,2\n")
    with pytest.raises(DataError, match=r"column 'u', data row 3: 'abc' is not a number"):
        read_columns(path, ["u", "y"])


def test_empty_cell(tmp_path):
    path = tmp_path / "run.csv"
    path.write_text("u,y\n1,2\n,2\n")
    with pytest.raises(DataError, match=r"column 'u', data row 2: '\(empty\)' is not a number"):
        read_columns(path, ["u", "y"])


@pytest.mark.parametrize("bad", ["nan", "inf", "-inf", "NaN"])
def test_non_finite_cell(tmp_path, bad):
    path = tmp_path / "run.csv"
    path.write_text(f"u,y\n1,2\n3,4\n5,{bad}\n")
    with pytest.raises(DataError, match=r"column 'y' has a non-finite value .* data row 3"):
        read_columns(path, ["u", "y"])


def test_non_finite_in_npz(tmp_path):
    path = tmp_path / "run.npz"
    np.savez(path, u=np.array([1.0, np.nan]), y=np.zeros(2))
    with pytest.raises(DataError, match=r"'u' has a non-finite value \(nan\) at data row 2"):
        read_columns(path, ["u", "y"])


def test_short_csv_row(tmp_path):
    path = tmp_path / "run.csv"
    path.write_text("u,y\n1,2\n3\n")
    with pytest.raises(DataError, match=r"data row 2 has 1 fields, the header has 2"):
        read_columns(path, ["u", "y"])


def test_unequal_lengths_npz(tmp_path):
    path = tmp_path / "run.npz"
    np.savez(path, u=np.zeros(5), y=np.zeros(4))
    with pytest.raises(DataError, match=r"unequal lengths \('u': 5, 'y': 4\)"):
        read_columns(path, ["u", "y"])


def test_empty_files(tmp_path):
    path = tmp_path / "empty.csv"
    path.write_text("")
    with pytest.raises(DataError, match=r"empty file"):
        read_columns(path, ["u"])
    path.write_text("u,y\n")
    with pytest.raises(DataError, match=r"no data rows"):
        read_columns(path, ["u"])
    npz = tmp_path / "empty.npz"
    np.savez(npz, u=np.zeros(0))
    with pytest.raises(DataError, match=r"no data rows"):
        read_columns(npz, ["u"])


def test_name_asked_of_a_headerless_file(tmp_path):
    path = tmp_path / "run.csv"
    path.write_text("1,2\n3,4\n")
    with pytest.raises(DataError, match=r"no column named 'u': the file has no header row "
                       r"\(its first row holds numbers\), so its 2 columns are known by "
                       r"number only, 1 to 2"):
        read_columns(path, ["u"])


def test_matrix_is_not_a_column(tmp_path):
    path = tmp_path / "run.mat"
    scipy.io.savemat(path, {"m": np.zeros((3, 4))})
    with pytest.raises(DataError, match=r"'m' is a 3x4 numeric array, not a numeric vector"):
        read_columns(path, ["m"])


def _write_matrix(path, m):
    """``m`` (rows = samples) as a user stores one matrix of signals in each format."""
    suffix = path.suffix
    if suffix == ".mat" and path.stem.endswith("73"):  # MATLAB v7.3: column-major
        with h5py.File(path, "w", userblock_size=512) as fh:
            fh.create_dataset("data", data=m.T).attrs["MATLAB_class"] = np.bytes_("double")
        with open(path, "r+b") as fh:
            fh.write(b"MATLAB 7.3 MAT-file".ljust(116, b" ") + b"\x00" * 8 + b"\x00\x02IM")
    elif suffix == ".mat":
        scipy.io.savemat(path, {"data": m})
    elif suffix == ".h5":
        with h5py.File(path, "w") as fh:
            fh.create_dataset("log/data", data=m)
    else:
        np.savez(path, data=m)


@pytest.mark.parametrize("name", ["run.mat", "run73.mat", "run.h5", "run.npz"])
def test_columns_of_a_stored_matrix_by_name_and_number(tmp_path, record, name):
    m = np.column_stack([record["t"], record["u"], record["y"]])
    path = tmp_path / name
    _write_matrix(path, m)
    var = "log/data" if name.endswith(".h5") else "data"
    table = read_columns(path, [f"{var}:3", f"{var}:2"], time_column=f"{var}:1")
    assert table.time_column == f"{var}:1"
    assert_array_equal(table[f"{var}:2"], record["u"])  # MATLAB's data(:, 2)
    assert_array_equal(table[f"{var}:3"], record["y"])
    assert sample_rate(table) == pytest.approx(1000.0, rel=1e-12)
    with pytest.raises(DataError, match=rf"'{var}:4': '{var}' has 3 columns \(257 rows"):
        read_columns(path, [f"{var}:4"])
    with pytest.raises(DataError, match=rf"no column '{var}:0'"):
        read_columns(path, [f"{var}:0"])


def test_a_vector_has_no_numbered_columns(tmp_path, record):
    path = tmp_path / "run.npz"
    np.savez(path, u=record["u"])
    with pytest.raises(DataError, match=r"'u:1': 'u' is a 257 array, not a numeric matrix"):
        read_columns(path, ["u:1"])
    with pytest.raises(DataError, match=r"no column '2'.*NAME:K"):
        read_columns(path, ["2"])


# ----------------------------------------------------------------------------- sample rate


def test_sample_rate_from_fs_only():
    assert sample_rate(None, 500) == 500.0


def test_sample_rate_needs_something(tmp_path):
    path = tmp_path / "run.csv"
    write_csv(path, {"u": [1.0, 2.0]})
    with pytest.raises(DataError, match=r"pass --fs"):
        sample_rate(read_columns(path))


def test_sample_rate_disagreement():
    t = np.arange(100) / 1000.0
    assert sample_rate(t, 1000.0) == 1000.0
    with pytest.raises(DataError, match=r"1000 Hz but --fs is 500 Hz"):
        sample_rate(t, 500.0)


def test_uneven_time_names_row(tmp_path):
    t = np.arange(20) / 1000.0
    t[12:] += 0.001  # one sample dropped between data rows 12 and 13
    path = tmp_path / "run.csv"
    write_csv(path, {"t": t, "u": np.zeros(20)})
    with pytest.raises(DataError, match=r"at data row 12 to .* at row 13, 2 typical steps"):
        sample_rate(read_columns(path))


def test_time_not_increasing():
    with pytest.raises(DataError, match=r"repeats the time 0.0 s at data rows 1 and 2; .* "
                       r"\(it is constant\)"):
        sample_rate(np.zeros(5))
    with pytest.raises(DataError, match=r"goes backwards from 0.003 s at data row 4 to "
                       r"0.002 s at row 5"):
        sample_rate([0.0, 0.001, 0.002, 0.003, 0.002, 0.005])


def test_bad_fs_value():
    with pytest.raises(DataError, match=r"fs=-1.0"):
        sample_rate(None, -1)


# ------------------------------------------------------------ headerless text, numbers


def _daisy_like(path, columns):
    """Whitespace-separated, right-aligned, no header: the layout of DaISy .dat files."""
    rows = np.column_stack(columns)
    path.write_text("".join("".join(f"{x:17.7e}" for x in row) + "\n" for row in rows))


def test_headerless_whitespace_file_by_number(tmp_path, rng):
    u, y = rng.standard_normal(50), rng.standard_normal(50)
    path = tmp_path / "dryer.dat"
    _daisy_like(path, [np.arange(50) * 0.08, u, y])
    table = read_columns(path, ["2", "3"], time_column="1")
    # 8 significant digits are written (%.7e): the read values are those decimals.
    assert_array_equal(table["2"], [float(f"{x:.7e}") for x in u])
    assert_array_equal(table["3"], [float(f"{x:.7e}") for x in y])
    assert table.time_column == "1" and table.label("2") == "column 2"
    assert sample_rate(table) == pytest.approx(12.5, rel=1e-12)
    everything = read_columns(path)
    assert list(everything) == ["1", "2", "3"]


def test_column_numbers_in_a_file_with_header(tmp_path, record):
    path = tmp_path / "run.csv"
    write_csv(path, record)
    table = read_columns(path, ["2", "y"])
    assert_array_equal(table["2"], record["u"])
    assert table.label("2") == "column 'u'"  # named by its header name in messages
    assert table.time_column == "t"


@pytest.mark.parametrize(
    ("spec", "match"),
    [
        ("0", r"there is no column 0; columns are numbered from 1 \(the first\) to 3"),
        ("4", r"no column 4; the file has 3 columns"),
        ("u", r"no column named 'u': the file has no header row"),
    ],
)
def test_bad_column_numbers(tmp_path, spec, match):
    path = tmp_path / "r.dat"
    _daisy_like(path, [np.arange(5.0), np.ones(5), np.zeros(5)])
    with pytest.raises(DataError, match=match):
        read_columns(path, [spec])


def test_column_number_in_a_binary_file_says_so(tmp_path, record):
    path = tmp_path / "run.npz"
    np.savez(path, **record)
    with pytest.raises(DataError, match=r"column numbers select columns of text files only"):
        read_columns(path, ["2"])


def test_semicolon_files_with_decimal_commas_are_read(tmp_path):
    # as spreadsheets write CSV in much of Europe; a point in a column name is no point
    # in the numbers
    path = tmp_path / "eu.csv"
    path.write_text("u.cmd;y\n1,5;2,5\n-3,25e-3;4\n")
    table = read_columns(path, ["u.cmd", "y"])
    assert table["u.cmd"].tolist() == [1.5, -3.25e-3]
    assert table["y"].tolist() == [2.5, 4.0]
    headerless = tmp_path / "eu_headerless.txt"
    headerless.write_text("1,5;2,5\n3;4,75\n")
    assert read_columns(headerless, ["2"])["2"].tolist() == [2.5, 4.75]


def test_decimal_commas_next_to_points_are_not_guessed(tmp_path):
    # 1.234,5 (a thousands point) or a mix of both: not read as decimal commas
    path = tmp_path / "mixed.csv"
    path.write_text("u;y\n1.234,5;2\n")
    with pytest.raises(DataError, match=r"column 'u', data row 1: '1.234,5' is not a number"):
        read_columns(path, ["u", "y"])
    path.write_text("u;y\n1,5;2\n1,25;2,5,0\n")
    with pytest.raises(DataError, match=r"column 'y', data row 2: '2,5,0' is not a number "
                                        r"\(read with decimal commas\)"):
        read_columns(path, ["u", "y"])


@pytest.mark.parametrize("sep", [",", " "])
@pytest.mark.parametrize("where", [1, 15_000, 29_999])
def test_field_count_checked_on_every_row(tmp_path, sep, where):
    # 30 000 rows: more than the first and last hundred, anywhere in the file.
    rows = [sep.join(["1", "2", "3"])] * 30_000
    rows[where - 1] = sep.join(["1", "2", "3", "4"])
    path = tmp_path / "big.csv"
    path.write_text(sep.join(["a", "b", "c"]) + "\n" + "\n".join(rows) + "\n")
    with pytest.raises(DataError, match=rf"data row {where} has 4 fields, the header has 3"):
        read_columns(path, ["a", "b"])


# ------------------------------------------------------------- degenerate time columns


@pytest.mark.parametrize(
    ("t", "match"),
    [
        (np.arange(10) * 1e-310, r"typical step of 1e-310 s, .* accepted rates are 1e-09 to "
                                 r"1e\+09 Hz"),
        (np.arange(10) * 1e300, r"typical step of 1e\+300 s, a sample rate of 1e-300 Hz"),
        (1e15 + np.arange(1000) * 1e-3, r"where a float resolves only 0.125 s.* subtract the "
                                      r"start time"),
        (np.array([0.0]), r"needs at least 2 samples"),
        (np.array([0.0, 1.0, 1.0, 2.0]), r"repeats the time 1.0 s at data rows 2 and 3"),
    ],
)
def test_degenerate_time_columns(t, match):
    with pytest.raises(DataError, match=match):
        sample_rate(t)


@pytest.mark.parametrize("fs", [0.0, -1.0, float("nan"), float("inf"), 1e10, 1e-10])
def test_fs_outside_the_accepted_rates(fs):
    with pytest.raises(DataError, match=r"must be in \[1e-09, 1e\+09\] Hz"):
        sample_rate(None, fs)


def test_columns_must_be_strings(tmp_path, record):
    path = tmp_path / "run.csv"
    write_csv(path, record)
    with pytest.raises(TypeError, match=r"written as strings \('2' for the second column\), "
                       r"not int 2"):
        read_columns(path, [2])
    with pytest.raises(TypeError, match="time_column"):
        read_columns(path, ["u"], time_column=1)
