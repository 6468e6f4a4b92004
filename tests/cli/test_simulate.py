"""``ehss simulate``: outputs, sidecar, plot, and one-line errors with nothing left behind."""

from __future__ import annotations

import json

import numpy as np
import pytest

from ehss.cli import main


def _reference_file(tmp_path, n=400, fs=1000.0, column="reference", with_t=True):
    t = np.arange(n) / fs
    # a smooth 2 mm move in 0.1 s (0.03 m/s peak): inside every limit
    r = 0.002 * np.clip((t - 0.05) / 0.1, 0, 1) ** 2 * (3 - 2 * np.clip((t - 0.05) / 0.1, 0, 1))
    cols = (["t"] if with_t else []) + [column]
    data = np.column_stack(([t] if with_t else []) + [r])
    f = tmp_path / "ref.csv"
    np.savetxt(f, data, delimiter=",", header=",".join(cols), comments="")
    return f


def test_reference_file_writes_csv_json_png(tmp_path):
    ref = _reference_file(tmp_path)
    out = tmp_path / "run.csv"
    png = tmp_path / "run.png"
    code = main(["simulate", "--loop", "position", "--reference", str(ref), "--out", str(out),
                 "--plot", str(png), "--seed", "3"])
    assert code == 0
    data = np.genfromtxt(out, delimiter=",", names=True)
    assert data.dtype.names[:3] == ("t", "reference", "output")
    assert data.shape == (400,)
    assert abs(data["output"][-50:].mean() - 0.002) < 1e-4
    meta = json.loads((tmp_path / "run.json").read_text())
    assert set(meta["units"]) == set(data.dtype.names)
    assert meta["loop"] == "position" and meta["seed"] == 3 and meta["fs_hz"] == 1000.0
    assert meta["params"]["load"]["mass_kg"] == 250.0
    assert {"ehss", "numpy", "numba"} <= set(meta["versions"])
    assert meta["signal"]["kind"] == "file"
    assert png.stat().st_size > 1000
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ref.csv", "run.csv", "run.json",
                                                          "run.png"]


def test_reference_without_t_needs_fs(tmp_path, capsys):
    ref = _reference_file(tmp_path, with_t=False)
    out = tmp_path / "run.csv"
    assert main(["simulate", "--loop", "position", "--reference", str(ref),
                 "--out", str(out)]) == 2
    assert "--fs" in capsys.readouterr().err
    assert main(["simulate", "--loop", "position", "--reference", str(ref), "--fs", "1000",
                 "--out", str(out)]) == 0


@pytest.mark.parametrize(
    ("extra", "text"),
    [
        (["--column", "nope"], "nope"),
        (["--fs", "3000"], "3000"),
    ],
)
def test_bad_input_exit_2_one_line_no_output(tmp_path, capsys, extra, text):
    ref = _reference_file(tmp_path)
    out = tmp_path / "run.csv"
    code = main(["simulate", "--loop", "position", "--reference", str(ref), "--out", str(out),
                 *extra])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and text in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ref.csv"]


def test_bad_file_exit_2(tmp_path, capsys):
    bad = tmp_path / "ref.csv"
    bad.write_text("t,reference\n0,0\n0.001,nan-ish\n")
    out = tmp_path / "run.csv"
    assert main(["simulate", "--loop", "force", "--reference", str(bad),
                 "--out", str(out)]) == 2
    assert capsys.readouterr().err.count("\n") == 1
    assert not out.exists() and not (tmp_path / "run.json").exists()


def test_missing_file_and_unwritable_output(tmp_path, capsys):
    out = tmp_path / "run.csv"
    assert main(["simulate", "--loop", "position", "--reference", str(tmp_path / "no.csv"),
                 "--out", str(out)]) == 2
    ref = _reference_file(tmp_path)
    assert main(["simulate", "--loop", "position", "--reference", str(ref),
                 "--out", str(tmp_path / "missing" / "run.csv")]) == 2
    assert capsys.readouterr().err.count("\n") == 2


def test_unknown_loop_is_an_argument_error(tmp_path):
    with pytest.raises(SystemExit) as info:
        main(["simulate", "--loop", "speed", "--signal", "step", "--out",
              str(tmp_path / "r.csv")])
    assert info.value.code == 2


@pytest.mark.parametrize(
    ("loop", "signal", "extra"),
    [
        ("position", "step", ["--amplitude", "0.005"]),
        ("acceleration", "sine", ["--freq", "10", "--amplitude", "1.0"]),
        ("force", "sweep", ["--offset", "245", "--amplitude", "7.4", "--band", "0.5", "20"]),
        ("position", "random", ["--amplitude", "0.0005", "--band", "2", "20"]),
        ("position", "multisine", ["--amplitude", "0.0005"]),
    ],
)
def test_generated_signals(tmp_path, loop, signal, extra):
    out = tmp_path / "run.csv"
    assert main(["simulate", "--loop", loop, "--signal", signal, "--duration", "1.0",
                 "--out", str(out), *extra]) == 0
    meta = json.loads((tmp_path / "run.json").read_text())
    assert meta["signal"]["kind"] and meta["n_samples"] == 1000


def test_infeasible_signal_exit_2(tmp_path, capsys):
    out = tmp_path / "run.csv"
    # 5 cm at 20 Hz needs 6 m/s: beyond the valve and Table 2
    assert main(["simulate", "--loop", "position", "--signal", "sine", "--amplitude", "0.05",
                 "--freq", "20", "--out", str(out)]) == 2
    assert capsys.readouterr().err.count("\n") == 1
    assert list(tmp_path.iterdir()) == []
