"""The validation's Welch segments follow the model's impulse response."""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.signal

from ehss.frequency import default_nperseg
from ehss.identification.model import ArmaxModel
from ehss.validation import segment_floor
from ehss.workflow import identify


@pytest.mark.parametrize("pole, delay", [(0.5, 3), (0.9, 1), (0.99, 0), (0.0, 12)])
def test_segment_floor_of_a_first_order_lag_with_dead_time(pole, delay):
    # h(k) = pole^(k − d) from k = d: |h| ≥ 1 % of its peak (1, at k = d) up to
    # k = d + floor(ln 0.01 / ln pole), so the memory is d + floor(...) + 1
    model = ArmaxModel(a=[1.0, -pole], b=[1.0], c=[1.0], delay=delay)
    tail = math.floor(math.log(0.01) / math.log(pole)) if pole > 0 else 0
    assert segment_floor(model, 20_000) == max(32 * delay, 4 * (delay + tail + 1))


def test_segment_floor_of_an_unstable_model_is_the_whole_record():
    model = ArmaxModel(a=[1.0, -1.01], b=[1.0], c=[1.0], delay=1)
    assert segment_floor(model, 5000) == 5000


def test_min_nperseg_lengthens_the_segment_only_as_far_as_the_record_affords():
    # 20 000 samples afford 4096 with 8 averages (8192 would leave 3); the band alone
    # asks for 1024
    band = (2.0, 100.0)
    assert default_nperseg(20_000, 1000.0, band_hz=band) == 1024
    assert default_nperseg(20_000, 1000.0, band_hz=band, min_nperseg=600) == 1024
    assert default_nperseg(20_000, 1000.0, band_hz=band, min_nperseg=1025) == 2048
    assert default_nperseg(20_000, 1000.0, band_hz=band, min_nperseg=10**6) == 4096
    # 30 000 samples: 8 averages allow 4096, a long memory may take 8192 (6 averages),
    # not 16384 (2)
    assert default_nperseg(30_000, 1000.0) == 4096
    assert default_nperseg(30_000, 1000.0, min_nperseg=5000) == 8192
    assert default_nperseg(30_000, 1000.0, min_nperseg=10**6) == 8192


@pytest.mark.slow
def test_a_loop_with_a_long_dead_time_is_validated_from_dc(rng):
    # a closed loop (40 Hz, ζ 0.6, a right-half-plane zero at 80 Hz) behind 20 samples
    # of dead time, driven by 0–300 Hz noise at 1 kHz. Segments of 128 samples (what
    # the band alone asks for) lose (1 − 20/128)² of the coherence: below 0.9 at every
    # low bin, and the band then started at 82 Hz. With segments that follow the model,
    # the comparison holds from the first bin and the band starts at DC.
    fs, delay = 1000.0, 20
    wn, wz = 2 * np.pi * 40.0, 2 * np.pi * 80.0
    bd, ad, _ = scipy.signal.cont2discrete(([-wn**2 / wz, wn**2], [1.0, 1.2 * wn, wn**2]),
                                           1 / fs, method="zoh")
    u = scipy.signal.lfilter(*scipy.signal.butter(4, 300.0, fs=fs), rng.standard_normal(60_000))
    y = scipy.signal.lfilter(np.r_[np.zeros(delay), np.ravel(bd)], ad, u)
    y = y + 0.01 * np.std(u) * rng.standard_normal(u.size)
    result = identify(u, y, fs=fs, orders=(2, 2, 2, delay))
    frf = result.report.frf
    assert frf.nperseg >= 32 * delay
    low = frf.freq_hz < 20.0
    assert np.all(frf.coherence[low] > 0.95)
    assert result.model.band_hz[0] == 0.0
    assert result.verdict.accepted
