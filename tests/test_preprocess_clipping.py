"""A clipped output is found and said before it is identified."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import lfilter

from ehss.errors import EhssWarning
from ehss.preprocess import clipped_share
from ehss.workflow import identify


def test_clipped_share_counts_the_longer_extreme():
    x = np.array([0.0, 3.0, 3.0, 3.0, -1.0, -1.0, 2.0, 1.0])
    assert clipped_share(x) == (3 / 8, 3.0)
    assert clipped_share(-x) == (3 / 8, -3.0)
    assert clipped_share(np.ones(4)) == (1.0, 1.0)


def _record(seed=1, n=6000):
    rng = np.random.default_rng(seed)
    u = rng.standard_normal(n)
    y = lfilter([0.0, 0.2, 0.1], [1.0, -1.3, 0.6], u) + 0.01 * rng.standard_normal(n)
    return u, y


def test_an_unclipped_record_raises_nothing():
    # filterwarnings = error: a warning fails this test. Noise-free ADC counts repeat
    # values, but a response reaches its extremes at a handful of samples only
    u, y = _record()
    identify(u, np.round(y * 100), fs=1000.0, orders=(2, 1, 0, 1))


def test_a_clipped_output_is_said():
    u, y = _record()
    top = np.percentile(y, 97)                    # 3 % of the samples at the rail
    with pytest.warns(EhssWarning, match=rf"output sits at {top:.6g} for 3 % of the record"):
        identify(u, np.minimum(y, top), fs=1000.0, orders=(2, 1, 0, 1))
