from __future__ import annotations

import numpy as np
from scipy import signal as sps

from ehss.experiments.loop_identification import Record, convergence
from ehss.identification import rels


def test_online_replay_ends_on_the_batch_estimate(rng):
    u = rng.standard_normal(3000)
    y = sps.lfilter([0.0, 0.3, 0.1], [1.0, -1.2, 0.5], u) + 0.01 * rng.standard_normal(3000)
    model = rels(u[:2000], y[:2000], na=2, nb=1, nc=1, delay=1, dt=1e-3)
    rec = Record(u=u, y=y, n_ident=2000, fs=1000.0, band_hz=(1.0, 100.0), frf=None,
                 y_band=y, lowpass=None, input_mean=0.0, output_mean=0.0)
    t, hist = convergence(rec, model, forgetting=1.0, p0=1.0e6, every=10)
    assert hist.shape == (200, model.theta.size)
    assert t[-1] == 2.0
    # Same compiled step, same scaling: the streaming replay ends bit-for-bit on the
    # batch estimate, up to the de-scaling of b (one multiplication).
    np.testing.assert_allclose(hist[-1], model.theta, rtol=1e-12, atol=1e-15)
