"""Online and offline agree: ehss live on a replayed record gives ehss.rels' estimate."""

from __future__ import annotations

import numpy as np
import pytest

import ehss
from ehss.cli import main
from ehss.live import read_recording, rig_record


@pytest.mark.parametrize("method, nc", [("rels", 0), ("rml", 4)])
def test_live_replay_equals_batch_rels(tmp_path, method, nc):
    layout, x, fs = rig_record("position", n_channels=1, duration_s=12.0, seed=3)
    path = tmp_path / "run.csv"
    ehss.write_csv(path, {name: x[:, i] for i, name in enumerate(layout.fields)})
    u, y = x[:, 1], x[:, 2]
    su, sy = float(np.sqrt(np.mean(u**2))), float(np.sqrt(np.mean(y**2)))
    lam = 0.999
    code = main(["live", "--replay", str(path), "--speed", "inf", "--quiet",
                 "--forgetting", str(lam), "--p0", "1000", "--na", "4", "--nb", "3",
                 "--nc", str(nc), "--method", method, "--u-scale", repr(su), "--y-scale", repr(sy),
                 "--record", str(tmp_path / "rec.h5")])
    assert code == 0
    rec = read_recording(tmp_path / "rec.h5")
    model = ehss.rels(u, y, na=4, nb=3, nc=nc, delay=1, forgetting=lam, p0=1000.0,
                      dt=1 / fs, method=method)
    assert rec["t"][-1] == x.shape[0] / fs
    # the same kernel on the same samples, but rels scales by u/s and the estimator by
    # u·(1/s): the scaled data differ in the last bit (ε = 1.1e-16), and the estimate's
    # sensitivity to its data is the condition number κ of the regressors' weighted
    # covariance (λ-weighted over the memory 1/(1−λ)); bound: 100 ε κ
    # (the a- and b-part of the regressor; the c-part is the residual history)
    phi = np.column_stack([-y[3:-1], -y[2:-2], -y[1:-3], -y[:-4],
                           u[3:-1], u[2:-2], u[1:-3], u[:-4]])[-1000:]
    phi /= np.r_[[sy] * 4, [su] * 4]
    kappa = np.linalg.cond(phi.T @ phi)
    rtol = 100 * np.finfo(float).eps * kappa
    assert rtol < 1e-6, kappa  # the comparison must still mean something
    np.testing.assert_allclose(rec["theta"][-1, 0], model.theta, rtol=rtol,
                               atol=rtol * np.abs(model.theta).max())
    np.testing.assert_array_equal(rec["samples"], x)


def test_a_record_with_its_own_column_names_replays_as_the_same_run(tmp_path, capsys):
    # the same samples under the canonical names and under a user's own: the same run,
    # bit for bit (same kernel, same order of samples)
    layout, x, fs = rig_record("position", n_channels=1, duration_s=3.0, seed=5)
    canonical, own = tmp_path / "canonical.csv", tmp_path / "own.csv"
    ehss.write_csv(canonical, {name: x[:, i] for i, name in enumerate(layout.fields)})
    names = {"t": "time_s", "ref1": "cmd_mm", "fb1": "pos_mm"}
    # the file's columns in another order than the fields, plus one that is not replayed
    ehss.write_csv(own, {"pos_mm": x[:, layout.fields.index("fb1")],
                         "spare": np.zeros(x.shape[0]),
                         "time_s": x[:, layout.fields.index("t")],
                         "cmd_mm": x[:, layout.fields.index("ref1")]})
    common = ["--speed", "inf", "--quiet", "--na", "2", "--nb", "2", "--nc", "0"]
    assert main(["live", "--replay", str(canonical), "--fields", "t,ref1,fb1",
                 "--record", str(tmp_path / "a.h5"), *common]) == 0
    fields = ",".join(f"{f}={c}" for f, c in names.items())
    assert main(["live", "--replay", str(own), "--fields", fields,
                 "--record", str(tmp_path / "b.h5"), *common]) == 0
    a, b = read_recording(tmp_path / "a.h5"), read_recording(tmp_path / "b.h5")
    np.testing.assert_array_equal(b["samples"], a["samples"])
    np.testing.assert_array_equal(b["theta"], a["theta"])
    assert b["fs"] == a["fs"] == fs
    capsys.readouterr()
    # half-renamed fields, a missing column, or renaming a live recording's fields
    for argv, words in (
        (["--replay", str(own), "--fields", "t=time_s,ref1,fb1=pos_mm"], "FIELD=COLUMN"),
        (["--replay", str(own), "--fields", "t=time_s,ref1=cmd,fb1=pos_mm"], "cmd"),
        (["--replay", str(tmp_path / "a.h5"), "--fields", "t=t,ref1=ref1,fb1=fb1"],
         "live recording"),
    ):
        assert main(["live", *argv, *common]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and words in err, err
