"""The figures of an identified loop that engineers follow over a campaign.

A falling natural frequency of the dominant poles means a softer oil column (air in the
oil, a leak, a lower bulk modulus: ωh = sqrt(4βe·Ap² / (Vt·m)), eq (4) of the paper); a
falling DC gain or bandwidth a weaker valve; a growing delay a slower controller or
valve.
"""

from __future__ import annotations

import math

import numpy as np

from ehss.identification import ArmaxModel

__all__ = ["FIGURES", "FIGURE_UNITS", "loop_figures"]

#: The figures, in the order the results list them.
FIGURES = ("natural_freq_hz", "damping", "dc_gain", "bandwidth_hz", "delay_s")
#: Their units, for tables and plots.
FIGURE_UNITS = {"natural_freq_hz": "Hz", "damping": "", "dc_gain": "",
                "bandwidth_hz": "Hz", "delay_s": "s"}
_GRID = 4096


def _dominant(poles: np.ndarray, dt: float) -> tuple[float, float]:
    """Natural frequency (Hz) and damping of the dominant poles.

    The dominant poles are the complex pair closest to the unit circle (the slowest to
    decay: the resonance a loop's response shows); without a complex pair, the real
    pole closest to the unit circle (damping 1). Each pole z maps to s = ln(z)/dt:
    ωn = |s|, ζ = −Re(s)/|s|. The validated band does not restrict the choice: it
    varies from record to record with the coherence, and the figure must not.
    """
    p = poles[np.abs(poles) > 0]
    if p.size == 0:
        return math.nan, math.nan
    s = np.log(p.astype(complex)) / dt
    wn_hz = np.abs(s) / (2 * math.pi)
    pair = p.imag > 1e-9
    pick = pair if pair.any() else np.isclose(p.imag, 0.0)
    if not pick.any():
        return math.nan, math.nan
    i = np.flatnonzero(pick)[np.argmax(np.abs(p[pick]))]
    return float(wn_hz[i]), float(-s[i].real / abs(s[i]))


def _bandwidth_hz(model: ArmaxModel, dc: float) -> float:
    """The first frequency where the gain falls 3 dB below the DC gain (NaN when the DC
    gain is 0 or the gain never falls that far below the Nyquist frequency)."""
    if not (math.isfinite(dc) and abs(dc) > 0):
        return math.nan
    f = np.linspace(0.0, 0.5 / model.dt, _GRID)
    mag = np.abs(model.frequency_response(f))
    below = np.flatnonzero(mag < abs(dc) / math.sqrt(2.0))
    if below.size == 0:
        return math.nan
    k = below[0]
    if k == 0:
        return 0.0
    # linear interpolation of the crossing between grid points k-1 and k
    m0, m1, level = mag[k - 1], mag[k], abs(dc) / math.sqrt(2.0)
    return float(f[k - 1] + (f[k] - f[k - 1]) * (m0 - level) / (m0 - m1))


def loop_figures(model: ArmaxModel) -> dict[str, float]:
    """Natural frequency (Hz) and damping of the dominant poles, DC gain, bandwidth
    (−3 dB from the DC gain, Hz) and the model's input delay (s).

    Parameters
    ----------
    model : ArmaxModel
        An identified loop.

    Returns
    -------
    dict of str to float
        Keyed by :data:`FIGURES`; NaN where a figure does not exist.
    """
    dc = float(model.dc_gain())
    wn, zeta = _dominant(np.asarray(model.poles()), model.dt)
    return {"natural_freq_hz": wn, "damping": zeta, "dc_gain": dc,
            "bandwidth_hz": _bandwidth_hz(model, dc), "delay_s": model.delay * model.dt}
