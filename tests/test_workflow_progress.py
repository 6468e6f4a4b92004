"""select_orders reports each validated candidate to a progress callback."""

from __future__ import annotations

import numpy as np
from scipy.signal import lfilter

from ehss.workflow import OrderGrid, select_orders


def test_progress_is_called_once_per_validated_candidate():
    rng = np.random.default_rng(2)
    u = rng.standard_normal(3000)
    y = lfilter([0.0, 0.2, 0.1], [1.0, -1.3, 0.6], u) + 0.01 * rng.standard_normal(u.size)
    lines: list[str] = []
    search = select_orders(u, y, fs=1000.0,
                           grid=OrderGrid(na=[1, 2], nb=[0, 1], nc=[0], delay=1),
                           progress=lines.append)
    validated = [r for r in search.reports if r is not None]
    assert len(lines) == len(validated) == 4
    fits = {f"({r.na},{r.nb},{r.nc},{r.delay}): fit {rep.fit_pct:.1f} %"
            for r, rep in zip(search.table, search.reports, strict=True) if rep is not None}
    assert set(lines) == fits
