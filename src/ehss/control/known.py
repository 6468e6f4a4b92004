"""Known factors of a closed loop: parts the user knows exactly and need not identify.

The acceleration loop's transfer function from the reference a_r to the measured
acceleration contains two slow high-passes whose corners sit near 0.5 Hz, far below the
2–100 Hz identification test of the paper: the acceleration generator of the controller,
eq (10), GAR(s)·s² = Kg s²/(s² + ωg s + δg), and the accelerometer's AC coupling
s/(s + ωa). A 2–100 Hz record hardly excites them, so a recursive estimator at 1 kHz
(where their poles sit at z ≈ 0.997) misses the phase lead they give at a few hertz.
Both are known exactly — the first is code in the controller, the second is on the
sensor's data sheet — so the identification can take them out of the input, identify
only the rest, and compose the complete model afterwards
(:func:`ehss.identification.known.compose`):

.. math:: G(q) = F(q)\\,G_{rest}(q), \\qquad u_f = F(q)\\,a_r, \\quad y = G_{rest}(q)\\,u_f

The accelerometer coupling is inside the loop (the controller feeds the measured
acceleration back through Kaf), so treating it as an output factor is an approximation;
it is good where the acceleration feedback is small against the displacement feedback,
that is at the low frequencies where the coupling matters.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import signal as sps

from ehss.control.discrete import generator_zoh
from ehss.errors import ParameterError
from ehss.params import RigParams

__all__ = ["generator_filter", "accelerometer_filter", "known_factors"]


def generator_filter(params: RigParams) -> tuple[np.ndarray, np.ndarray]:
    """Discrete a_r → a_d of the acceleration generator, eq (10), as the controller runs it.

    The controller integrates the generator state x = [r_d, v_d] exactly over each
    period (zero-order hold): x[k+1] = Φ x[k] + Γ a_r[k], and outputs
    a_d[k] = Kg a_r[k] − δg r_d[k] − ωg v_d[k]. Its transfer function is
    a_d/a_r = D + C (zI − Φ)⁻¹ Γ with C = [−δg, −ωg], D = Kg.

    Returns
    -------
    num, den : ndarray, shape (3,)
        Coefficients in ascending powers of q⁻¹, den[0] = 1.
    """
    g = params.acceleration
    dt = params.timing.dt_s
    wg = 2.0 * g.generator_damping * g.generator_omega_rad_s
    dg = g.generator_omega_rad_s**2
    phi, gam = generator_zoh(g.kg, wg, dg, dt)
    c1, c2 = -dg, -wg
    # det(zI − Φ) = z² − tr(Φ) z + det(Φ)
    den = np.array([1.0, -(phi[0, 0] + phi[1, 1]), phi[0, 0] * phi[1, 1] - phi[0, 1] * phi[1, 0]])
    # C adj(zI − Φ) Γ = z (c1 γ1 + c2 γ2) + (c1(Φ12 γ2 − Φ22 γ1) + c2(Φ21 γ1 − Φ11 γ2))
    k1 = c1 * gam[0] + c2 * gam[1]
    k0 = c1 * (phi[0, 1] * gam[1] - phi[1, 1] * gam[0]) + c2 * (
        phi[1, 0] * gam[0] - phi[0, 0] * gam[1]
    )
    num = g.kg * den + np.array([0.0, k1, k0])
    return num, den


def accelerometer_filter(params: RigParams) -> tuple[np.ndarray, np.ndarray]:
    """Discrete AC coupling s/(s + ωa) of the accelerometer (bilinear transform).

    Returns ``([1.0], [1.0])`` when the coupling is switched off (corner 0 Hz).
    """
    wa = 2.0 * math.pi * params.sensors.accel_highpass_hz
    if wa == 0.0:
        return np.array([1.0]), np.array([1.0])
    num, den = sps.bilinear([1.0, 0.0], [1.0, wa], fs=params.timing.control_rate_hz)
    return np.asarray(num, dtype=float) / den[0], np.asarray(den, dtype=float) / den[0]


def known_factors(loop: str, params: RigParams) -> tuple[np.ndarray, np.ndarray]:
    """Product F(q) of the known factors of ``loop`` (ascending powers of q⁻¹).

    The acceleration loop has the generator and the accelerometer coupling; the position
    and force loops have none (F = 1).
    """
    if loop == "acceleration":
        n1, d1 = generator_filter(params)
        n2, d2 = accelerometer_filter(params)
        return np.polymul(n1, n2), np.polymul(d1, d2)
    if loop in ("position", "force"):
        return np.array([1.0]), np.array([1.0])
    raise ParameterError(f"loop={loop!r} must be 'position', 'acceleration' or 'force'")
