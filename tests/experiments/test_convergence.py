from __future__ import annotations

import numpy as np
from scipy import signal as sps

from ehss.experiments.loop_identification import convergence, loop_record
from ehss.identification import rels


def test_online_replay_ends_on_the_batch_estimate(rng):
    u = rng.standard_normal(3000)
    y = sps.lfilter([0.0, 0.3, 0.1], [1.0, -1.2, 0.5], u) + 0.01 * rng.standard_normal(3000)
    rec = loop_record(u, y, fs=1000.0, band_hz=(1.0, 100.0), holdout=1 / 3)
    assert rec.n_ident == 2000
    # the estimation part the programme fits on: the first 2000 samples about their mean
    model = rels(rec.prepared.u, rec.prepared.y, na=2, nb=1, nc=1, delay=1, dt=1e-3)
    t, hist = convergence(rec, model, forgetting=1.0, p0=1.0e6, every=10)
    assert hist.shape == (200, model.theta.size)
    assert t[-1] == 2.0
    # Same compiled step, same scaling: the streaming replay ends bit-for-bit on the
    # batch estimate, up to the de-scaling of b (one multiplication).
    np.testing.assert_allclose(hist[-1], model.theta, rtol=1e-12, atol=1e-15)
