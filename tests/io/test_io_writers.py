"""CSV and JSON writers: exact values, JSON-safe conversions, nothing half-written."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from ehss.errors import DataError
from ehss.io import read_columns, to_jsonable, write_csv, write_json


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
