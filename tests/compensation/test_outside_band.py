"""A reference mostly outside the model's band is compensated little, and that is said."""

from __future__ import annotations

import json

import numpy as np
import pytest

from ehss.cli import main
from ehss.compensation import OUTSIDE_SHARE_WARN, compensate
from ehss.errors import EhssWarning
from ehss.identification.model import ArmaxModel

FS, N = 1000.0, 20000


def _tones(freqs_hz, amps):
    """Tones under a sin² envelope: at rest at both ends."""
    t = np.arange(N) / FS
    env = np.sin(np.pi * np.arange(N) / (N - 1)) ** 2
    return env * sum(a * np.sin(2 * np.pi * f * t) for f, a in zip(freqs_hz, amps, strict=True))


MODEL = ArmaxModel(a=[1.0, -0.5], b=[1.0], delay=1, dt=1 / FS, band_hz=(4.0, 50.0))


def test_a_reference_in_the_band_raises_nothing():
    # filterwarnings = error: any warning fails this test
    compensate(MODEL, _tones([10.0, 30.0], [1.0, 0.5]), fs=FS)


@pytest.mark.parametrize(("amps", "share"), [([1.0, 1.0], 0.5), ([1.0, 0.0], 1.0)])
def test_the_share_outside_is_said(amps, share):
    # tones at 1 Hz (outside 4-50 Hz) and 10 Hz of equal size: half the power outside
    assert share > OUTSIDE_SHARE_WARN
    with pytest.warns(EhssWarning, match=rf"{100 * share:.0f} % of the reference's power "
                                         r"lies outside the band 4-50 Hz"):
        compensate(MODEL, _tones([1.0, 10.0], amps), fs=FS)


def test_the_command_line_says_it_in_one_line(tmp_path, capsys):
    model = tmp_path / "m.json"
    model.write_text(json.dumps(MODEL.to_dict()))
    ref = tmp_path / "r.csv"
    np.savetxt(ref, np.c_[np.arange(N) / FS, _tones([1.0], [1e-3])], delimiter=",",
               header="t,reference", comments="")
    assert main(["compensate", str(model), str(ref), "--out", str(tmp_path / "d.csv")]) == 0
    lines = [ln for ln in capsys.readouterr().err.splitlines() if "warning" in ln]
    assert len(lines) == 1 and "100 % of the reference's power lies outside" in lines[0]
