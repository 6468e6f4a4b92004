"""A sample rate stored beside the columns (MATLAB's Ts, an fs attribute) is used."""

from __future__ import annotations

import h5py
import numpy as np
import pytest
import scipy.io

from ehss.errors import DataError
from ehss.io import read_columns, sample_rate

U = np.random.default_rng(6).standard_normal(500)


def _mat(path, **scalars):
    scipy.io.savemat(path, {"u": U, "y": U, **scalars})


def _h5(path, attrs=None, **scalars):
    with h5py.File(path, "w") as fh:
        fh["u"], fh["y"] = U, U
        for k, v in scalars.items():
            fh[k] = v
        fh.attrs.update(attrs or {})


@pytest.mark.parametrize(("write", "name", "rate"), [
    (lambda p: _mat(p, Ts=0.002), "r.mat", 500.0),              # iddata's sample time
    (lambda p: _mat(p, fs=2048.0), "r.mat", 2048.0),
    (lambda p: _h5(p, attrs={"fs": 5000.0}), "r.h5", 5000.0),
    (lambda p: _h5(p, dt=1e-3), "r.h5", 1000.0),
    (lambda p: np.savez(p, u=U, y=U, sample_rate=np.array(200.0)), "r.npz", 200.0),
])
def test_the_stored_rate_is_the_sample_rate(tmp_path, write, name, rate):
    path = tmp_path / name
    write(path)
    table = read_columns(path, ["u", "y"])
    assert sample_rate(table) == pytest.approx(rate, rel=1e-12)
    assert sample_rate(table, rate) == rate
    with pytest.raises(DataError, match=r"the file stores .* but --fs is"):
        sample_rate(table, 2 * rate)


def test_a_time_column_wins_and_vectors_named_like_a_rate_are_columns(tmp_path):
    path = tmp_path / "r.mat"
    scipy.io.savemat(path, {"u": U, "y": U, "t": np.arange(U.size) / 100.0, "Ts": 0.5,
                            "dt": U})
    assert sample_rate(read_columns(path, ["u", "y"])) == pytest.approx(100.0, rel=1e-12)
    no_time = read_columns(path, ["u", "y"], time_column=None)
    assert no_time.stored_rate == (2.0, "'Ts' = 0.5 s")        # 'dt' is a vector: a column


def test_without_any_rate_the_message_is_unchanged(tmp_path):
    path = tmp_path / "r.mat"
    _mat(path)
    with pytest.raises(DataError, match="no time column to get the sample rate from"):
        sample_rate(read_columns(path, ["u", "y"]))


@pytest.mark.parametrize(("write", "name", "opener"), [
    (lambda p: _h5(p, attrs={"fs": 5000.0}), "r.h5", (h5py, "File")),
    (lambda p: _mat(p, Ts=0.002), "r.mat", (scipy.io, "loadmat")),
    (lambda p: np.savez(p, u=U, y=U, fs=np.array(200.0)), "r.npz", (np, "load")),
])
def test_columns_and_stored_rate_come_from_one_opening(tmp_path, monkeypatch, write, name,
                                                       opener):
    path = tmp_path / name
    write(path)
    module, attr = opener
    real, calls = getattr(module, attr), []

    def counted(*args, **kwargs):
        calls.append(args)
        return real(*args, **kwargs)

    monkeypatch.setattr(module, attr, counted)
    if module is scipy.io:  # a second look at a MATLAB file would list its variables
        monkeypatch.setattr(scipy.io, "whosmat", counted)
    table = read_columns(path, ["u", "y"])
    assert table.stored_rate is not None
    assert len(calls) == 1
