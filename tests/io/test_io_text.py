"""Text records as users write them, read against a slow reference parser."""

from __future__ import annotations

import h5py
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.testing import assert_array_equal

from ehss.errors import DataError
from ehss.io import read_columns, sample_rate


def _reference(text: str, sep: str | None, decimal_comma: bool) -> list[list[float]]:
    """Rows of numbers by the slowest, plainest reading: split each line, float each
    field (independent of polars and of the reader's layout logic)."""
    rows = []
    for line in text.splitlines():
        fields = line.split() if sep is None else line.split(sep)
        rows.append([float(f.strip().replace(",", ".") if decimal_comma else f.strip())
                     for f in fields])
    return rows


_finite = st.floats(allow_nan=False, allow_infinity=False, width=64)


@settings(max_examples=30, deadline=None)
@given(
    values=st.lists(st.lists(_finite, min_size=3, max_size=3), min_size=2, max_size=20),
    sep=st.sampled_from([",", ";", "\t", " ", "   ", " , ", "; "]),
    header=st.booleans(),
    decimal_comma=st.booleans(),
    crlf=st.booleans(),
)
def test_any_layout_reads_as_the_reference(tmp_path_factory, values, sep, header,
                                           decimal_comma, crlf):
    decimal_comma = decimal_comma and sep.strip() == ";"
    cells = [[repr(x).replace(".", ",") if decimal_comma else repr(x) for x in row]
             for row in values]
    lines = [sep.join(row) for row in cells]
    names = ["a", "b", "c"]
    eol = "\r\n" if crlf else "\n"
    text = eol.join(([sep.join(names)] if header else []) + lines) + eol
    path = tmp_path_factory.mktemp("layout") / "r.txt"
    path.write_bytes(text.encode())
    split_on = sep.strip() or None
    # decimal commas are read only when no value has a point: repr writes "1e+20", so a
    # file of such values alone has none and is read with decimal commas either way
    expected = np.array(_reference(eol.join(lines), split_on, decimal_comma))
    keys = names if header else ["1", "2", "3"]
    table = read_columns(path, time_column=None)
    assert list(table) == keys
    for j, key in enumerate(keys):
        assert_array_equal(table[key], expected[:, j])  # repr: exact round trip


def test_spaces_around_fields_are_not_part_of_them(tmp_path):
    path = tmp_path / "r.csv"
    path.write_text("t , u,  y\n  0, 1.5 ,2\n0.5 ,  2.5,3  \n")
    table = read_columns(path, ["u", "y"])
    assert table["u"].tolist() == [1.5, 2.5] and table["y"].tolist() == [2.0, 3.0]
    assert table.time.tolist() == [0.0, 0.5]


@pytest.mark.parametrize(("text", "columns", "match"), [
    ("u,y\n1,2\n1 5,2\n", ["u", "y"], r"column 'u', data row 2: '1 5' is not a number"),
    # blank lines at the end are no rows; one inside the data is
    ("u,y\n1,2\n\n3,4\n\n\n", ["u", "y"], r"data row 2 is empty"),
    # Python's float() takes 1_000; a record does not hold it
    ("u,y\n1,2\n1_000,2\n", ["u", "y"], r"column 'u', data row 2: '1_000' is not a number"),
    # every row has the header's number of fields, also in columns not asked for
    ("u,note,y\n1,,2\n3,ok\n", ["u"], r"data row 2 has 2 fields, the header has 3"),
    ("u,note,y\n1,,2\n3,ok,4,5\n", ["u"], r"data row 2 has 4 fields, the header has 3"),
])
def test_a_bad_row_is_named(tmp_path, text, columns, match):
    path = tmp_path / "r.csv"
    path.write_text(text)
    with pytest.raises(DataError, match=match):
        read_columns(path, columns)


def test_an_empty_cell_in_a_column_not_asked_for_is_no_error(tmp_path):
    path = tmp_path / "r.csv"
    path.write_text("u,note,y\n1,,2\n3,ok,4\n")
    table = read_columns(path, ["u", "y"])
    assert table["u"].tolist() == [1.0, 3.0] and table["y"].tolist() == [2.0, 4.0]


def test_whitespace_rows_with_tabs_crlf_and_comments(tmp_path):
    path = tmp_path / "r.dat"
    # the first row is separated by spaces (a tab there would make it tab-separated)
    path.write_bytes(b"# DaISy-like\r\n\r\n  0.0   1.5   -2\r\n\t0.5 \t2.5e-3  3 \r\n\r\n")
    table = read_columns(path, ["2", "3"], time_column="1")
    assert table["2"].tolist() == [1.5, 2.5e-3] and table["3"].tolist() == [-2.0, 3.0]
    assert sample_rate(table) == 2.0


def test_a_latin1_header_keeps_its_names(tmp_path):
    path = tmp_path / "r.csv"
    path.write_bytes("t;Temp °C\n0;1,5\n1;2,5\n".encode("latin-1"))
    assert read_columns(path, ["Temp °C"])["Temp °C"].tolist() == [1.5, 2.5]


def test_a_mat73_sample_time_is_the_sample_rate(tmp_path):
    # MATLAB v7.3 keeps Ts as a 1-by-1 double dataset beside the columns
    path = tmp_path / "r73.mat"
    with h5py.File(path, "w", userblock_size=512) as fh:
        for name in ("u", "y"):
            fh.create_dataset(name, data=np.arange(10.0)[None, :])
            fh[name].attrs["MATLAB_class"] = np.bytes_("double")
        fh.create_dataset("Ts", data=np.array([[0.004]]))
        fh.create_group("fs")  # a group named like a rate is no rate
    table = read_columns(path, ["u", "y"])
    assert table.stored_rate == (250.0, "'Ts' = 0.004 s")
    assert sample_rate(table) == 250.0
