"""``ehss order``: the table, the best order, the CSV, and exit 2 on bad input."""

from __future__ import annotations

import numpy as np
import pytest

from ehss.cli import main
from ehss.cli._dataargs import int_list
from ehss.identification.model import ArmaxModel
from ehss.io import read_columns, write_csv

FS = 1000.0


@pytest.fixture
def data_csv(tmp_path, rng):
    m = ArmaxModel(a=[1.0, -1.5, 0.7], b=[0.1, 0.1], c=[1.0], delay=1, dt=1 / FS)
    n = 4000
    u = rng.standard_normal(n)
    y = m.simulate(u) + 0.005 * rng.standard_normal(n)
    path = tmp_path / "run.csv"
    write_csv(path, {"t": np.arange(n) / FS, "u": u, "y": y})
    return path


def test_order_table_and_best(tmp_path, data_csv, capsys):
    out = tmp_path / "orders.csv"
    code = main(["order", str(data_csv), "--input", "u", "--output", "y", "--na", "1-3",
                 "--nb", "0,1", "--nc", "0", "--delay", "1", "--criterion", "mdl",
                 "--out", str(out)])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    # The true orders (2, 1, 0) explain the data; MDL's penalty rejects the larger ones.
    assert "best by mdl: --na 2 --nb 1 --nc 0 --delay 1" in captured.out
    table = read_columns(out)
    assert list(table) == ["na", "nb", "nc", "delay", "n_params", "loss", "aic", "fpe",
                           "mdl", "fit_pct"]
    assert table.n_rows == 6
    best = int(np.argmin(table["mdl"]))
    assert (table["na"][best], table["nb"][best]) == (2, 1)
    assert table["fit_pct"][best] > 95  # held-out simulation fit of the true structure


def test_order_without_holdout(tmp_path, data_csv, capsys):
    code = main(["order", str(data_csv), "--input", "u", "--output", "y", "--na", "2",
                 "--nb", "1", "--nc", "0", "--holdout", "0"])
    assert code == 0
    assert "best by aic" in capsys.readouterr().out


@pytest.mark.parametrize(
    "extra,match",
    [
        (["--criterion", "fit", "--holdout", "0"], "--criterion fit needs --holdout > 0"),
        (["--holdout", "-0.1"], "--holdout -0.1 must be in [0, 1)"),
        (["--nc", "0-40", "--na", "1-20"], "500 or fewer"),
    ],
)
def test_order_bad_settings(tmp_path, data_csv, capsys, extra, match):
    base = {"--na": "1,2", "--nb": "1", "--nc": "0"}
    for k in list(base):
        if k in extra:
            base.pop(k)
    args = [a for kv in base.items() for a in kv]
    out = tmp_path / "o.csv"
    code = main(["order", str(data_csv), "--input", "u", "--output", "y", *args, *extra,
                 "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and match in err, err
    assert not out.exists()


def test_order_bad_data(tmp_path, capsys):
    path = tmp_path / "bad.csv"
    path.write_text("t,u,y\n0,1,2\n0.001,1,oops\n")
    code = main(["order", str(path), "--input", "u", "--output", "y", "--na", "1", "--nb",
                 "0", "--nc", "0"])
    err = capsys.readouterr().err
    assert code == 2 and "column 'y', data row 2: 'oops' is not a number" in err


def test_order_too_few_samples(tmp_path, rng, capsys):
    path = tmp_path / "short.csv"
    write_csv(path, {"t": np.arange(30) / FS, "u": rng.standard_normal(30),
                     "y": rng.standard_normal(30)})
    code = main(["order", str(path), "--input", "u", "--output", "y", "--na", "10", "--nb",
                 "10", "--nc", "5"])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1, err


def test_order_bad_list_is_argparse_error(data_csv, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["order", str(data_csv), "--input", "u", "--output", "y", "--na", "two",
              "--nb", "1", "--nc", "0"])
    assert exc.value.code == 2
    assert "not a list of integers" in capsys.readouterr().err


def test_int_list():
    assert int_list("2,3,4") == [2, 3, 4]
    assert int_list("2-4,7") == [2, 3, 4, 7]
    assert int_list("1:3") == [1, 2, 3]
    assert int_list("3,3") == [3]
