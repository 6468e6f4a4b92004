"""The band a reference's power lies in (`ehss.live.reference_band`): the default band of
live detection's figures and of adaptive compensation."""

import numpy as np
import pytest

import ehss
from ehss.errors import ParameterError
from ehss.live import reference_band


def _flat(band, fs, duration_s, seed=1):
    return ehss.signals.band_limited_random(band_hz=band, rms=1e-3, duration_s=duration_s,
                                            fs=fs, seed=seed, fade_s=0.2).values


@pytest.mark.parametrize("fs, band", [(4000.0, (1.0, 40.0)), (2000.0, (1.0, 50.0)),
                                      (1000.0, (0.5, 20.0))])
@pytest.mark.parametrize("seed", [1, 2, 3])
def test_a_long_record_finds_the_lower_edge_not_zero(fs, band, seed):
    # 40 s: bins 4x finer than 0.5 Hz fit 8 times; the 0-Hz bin of the coarse bins is
    # within 20 dB of the peak (the segments' mean removed), which put the band at 0 Hz
    lo, hi = reference_band(_flat(band, fs, 40.0, seed), fs)
    # each edge is found outside the band by at most Hann's main lobe (2 bins): the
    # lower one in the finer bins, the upper one in the coarse bins
    coarse = fs / 2 ** round(np.log2(fs / 0.5))
    assert band[0] - 2 * coarse / 4 <= lo <= band[0]
    assert band[1] <= hi <= band[1] + 2 * coarse


def test_a_short_record_starts_its_band_at_the_first_bin():
    # 4 s at 1 kHz hold no 8 segments of finer bins: the lowest a band can start is one bin
    fs = 1000.0
    lo, hi = reference_band(_flat((1.0, 40.0), fs, 4.0), fs)
    assert fs / 2048 <= lo <= 1.0
    assert 40.0 <= hi <= 40.0 + 2 * fs / 2048


def test_power_near_zero_hz_keeps_the_band_there():
    # a reference from 0.1 Hz: the band starts at the first of the finer bins
    fs = 1000.0
    lo, _ = reference_band(_flat((0.1, 10.0), fs, 80.0), fs)
    assert lo == pytest.approx(fs / 8192)


def test_an_offset_is_not_a_band():
    fs = 1000.0
    u = _flat((2.0, 20.0), fs, 40.0) + 0.05   # 50x the RMS as an offset
    lo, hi = reference_band(u, fs)
    coarse = fs / 2048
    assert 2.0 - 2 * coarse <= lo <= 2.0 and 20.0 <= hi <= 20.0 + 2 * coarse


def test_no_power_is_refused():
    with pytest.raises(ParameterError, match="no power"):
        reference_band(np.zeros(4000), 1000.0)
