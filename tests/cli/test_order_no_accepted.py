"""`ehss order` says so when no candidate meets the acceptance."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import lfilter

from ehss.cli import main


@pytest.mark.parametrize(("noise", "said"), [(1.0, True), (0.01, False)])
def test_no_accepted_candidate_is_said(tmp_path, capsys, noise, said):
    # a second-order loop, 4000 samples: with output noise of about the output's own
    # size no model can reach a 90 % simulation fit; with 1 % the (2, 1) candidate passes
    rng = np.random.default_rng(2)
    u = rng.standard_normal(4000)
    y = lfilter([0.0, 0.2, 0.1], [1.0, -1.3, 0.6], u) + noise * rng.standard_normal(u.size)
    path = tmp_path / "rec.csv"
    np.savetxt(path, np.c_[np.arange(u.size) / 1000.0, u, y], delimiter=",",
               header="t,u,y", comments="")
    assert main(["order", str(path), "--input", "u", "--output", "y", "--na", "1-2",
                 "--nb", "0-1", "--nc", "0"]) == 0
    err = capsys.readouterr().err
    assert ("no candidate meets the acceptance" in err) is said, err
