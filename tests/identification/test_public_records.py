"""The default workflow on two measured public records (tests/data/README.md).

order (default method, validation fit on the second half) → refit of its pick with the
same estimator on the first half → free-run fit on the second half. It must be stable and
within 0.5 fit points of, or above, the best plain least-squares ARX over the same order
grid and split, computed here independently with numpy.linalg.lstsq.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.signal import lfilter

from ehss.identification import estimate, select_order
from ehss.io import read_columns, sample_rate

DATA = Path(__file__).resolve().parents[1] / "data"

#: record → (na grid, nb grid, nc grid)
RECORDS = {
    "daisy_dryer.csv": (range(1, 6), range(0, 5), (1, 2)),
    "daisy_robot_arm.csv": (range(2, 9, 2), range(1, 8, 2), (2,)),
}


def _halves(name):
    table = read_columns(DATA / name, ["u", "y"], time_column="t")
    fs = sample_rate(table, None)
    u, y = table["u"], table["y"]
    n = u.size // 2
    # deviations from the estimation half's operating point, as ehss order does
    u, y = u - np.mean(u[:n]), y - np.mean(y[:n])
    return (u[:n], y[:n]), (u[n:], y[n:]), 1.0 / fs


def _fit(y, ysim):
    return 100.0 * (1.0 - np.linalg.norm(y - ysim) / np.linalg.norm(y - np.mean(y)))


def _best_plain_arx(est, val, na_grid, nb_grid, delay=1):
    """Best stable least-squares ARX by free-run fit (zero initial state) on val."""
    (u, y), (uv, yv) = est, val
    best = -np.inf
    for na in na_grid:
        for nb in nb_grid:
            k0 = max(na, nb + delay)
            phi = np.column_stack([-y[k0 - i : y.size - i] for i in range(1, na + 1)]
                                  + [u[k0 - delay - j : u.size - delay - j]
                                     for j in range(nb + 1)])
            theta = np.linalg.lstsq(phi, y[k0:], rcond=None)[0]
            a = np.concatenate([[1.0], theta[:na]])
            if np.max(np.abs(np.roots(a))) >= 1.0:
                continue
            ysim = lfilter(np.concatenate([np.zeros(delay), theta[na:]]), a, uv)
            best = max(best, _fit(yv, ysim))
    return best


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(RECORDS))
def test_default_workflow_is_stable_and_at_least_plain_arx(name):
    est, val, dt = _halves(name)
    na_grid, nb_grid, nc_grid = RECORDS[name]
    sel = select_order(*est, na=list(na_grid), nb=list(nb_grid), nc=list(nc_grid), delay=1,
                       dt=dt, validation=val)
    assert sel.criterion == "fit" and sel.method == "armax"
    b = sel.best
    model = estimate(*est, method=sel.method, na=b.na, nb=b.nb, nc=b.nc, delay=b.delay, dt=dt)
    assert model.is_stable()
    fit = _fit(val[1], model.simulate(val[0]))
    # the refit is the same model (deterministic estimator, same data)
    assert fit == pytest.approx(b.fit, abs=1e-9)
    reference = _best_plain_arx(est, val, na_grid, nb_grid)
    assert np.isfinite(reference)
    assert fit >= reference - 0.5, (fit, reference)
