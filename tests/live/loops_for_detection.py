"""Loops other than the simulated rig, as linear state-space models (scipy), for the
change-detection tests: each returns a live record ``(layout, samples, fs)`` like
:func:`ehss.live.rig_record`, with a parameter that may change at a given time.

* :func:`servo_record`: a position loop whose closed-loop response is a second-order
  mode (25 Hz, ζ = 0.4) behind a valve (80 Hz, ζ = 0.7), at 2 kHz;
* :func:`specimen_record`: a servo-hydraulic actuator pushing a specimen spring, at
  4 kHz: valve lag, piston and specimen mass on the oil column's stiffness and the
  spring, proportional position control;
* :data:`HIGH_PASS` (:func:`loop_record`): a 30 Hz mode behind a 0.5 Hz
  second-order high-pass (an AC-coupled sensor, an acceleration generator), at 1 kHz;
* :data:`DELAYED`: a 12 Hz, ζ = 0.5 loop behind 2 ms of delay, at 1 kHz;
* :data:`OIL_COLUMN`: a 15 Hz, ζ = 0.7 loop with a lightly damped oil-column mode
  (40 Hz, ζ = 0.15), at 2 kHz;
* :data:`LAGGED`: an 8 Hz, ζ = 0.6 loop behind a 30 Hz first-order lag, at 1 kHz.

Each channel's reference is band-pass filtered random noise and its feedback carries white
sensor noise of 1 % of the feedback's RMS (seeds per channel). A change multiplies one
physical parameter by ``factor`` from ``change_s`` on, the state carried over.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import control
import numpy as np
from numba import njit
from scipy.signal import StateSpace, butter, cont2discrete, sosfilt, tf2ss

from ehss.live.rig import rig_layout

__all__ = ["servo_record", "specimen_record", "loop_record", "LoopSpec", "SERVO",
           "SPECIMEN", "HIGH_PASS", "DELAYED", "OIL_COLUMN", "LAGGED", "discrete",
           "simulate_states",
           "reference"]


def _servo_ss(wn_scale: float) -> StateSpace:
    """Closed-loop position response: valve (80 Hz, ζ 0.7) then a 25 Hz, ζ 0.4 mode
    whose natural frequency is scaled by ``wn_scale`` (a mass × m scales it by 1/√m)."""
    wv, zv = 2 * math.pi * 80.0, 0.7
    wn, zn = 2 * math.pi * 25.0 * wn_scale, 0.4
    # states: valve q, q', position x, x'
    a = np.array([[0, 1, 0, 0],
                  [-wv**2, -2 * zv * wv, 0, 0],
                  [0, 0, 0, 1],
                  [wn**2, 0, -wn**2, -2 * zn * wn]])
    b = np.array([[0.0], [wv**2], [0.0], [0.0]])
    c = np.array([[0.0, 0.0, 1.0, 0.0]])
    return StateSpace(a, b, c, np.zeros((1, 1)))


def _specimen_ss(stiffness_scale: float) -> StateSpace:
    """An actuator (piston area A, moving mass m) on its oil column (bulk modulus β,
    volume V, leakage C_l) pushing a specimen spring k_s·``stiffness_scale``; a valve
    with a first-order lag (150 Hz) and flow gain K_q; a proportional position
    controller K_p. Load flow Q = K_q x_v; (V / 4β) ṗ = Q − A ẋ − C_l p;
    m ẍ = A p − c ẋ − k_s x."""
    area, mass, damping = 2.0e-3, 200.0, 1.0e4
    beta, volume, leak = 1.4e9, 1.0e-3, 5.0e-11
    k_s = 1.0e7 * stiffness_scale
    tau_v = 1 / (2 * math.pi * 150.0)
    k_q = 0.5                      # m³/s per unit spool
    k_p = 2 * math.pi * 20.0 * area / k_q   # crossover near 20 Hz without the spring
    ch = volume / (4 * beta)
    # states: spool x_v, load pressure p, position x, velocity v; input r
    a = np.array([
        [-1 / tau_v, 0, -k_p / tau_v, 0],
        [k_q / ch, -leak / ch, 0, -area / ch],
        [0, 0, 0, 1],
        [0, area / mass, -k_s / mass, -damping / mass],
    ])
    b = np.array([[k_p / tau_v], [0.0], [0.0], [0.0]])
    c = np.array([[0.0, 0.0, 1.0, 0.0]])
    return StateSpace(a, b, c, np.zeros((1, 1)))


def _high_pass_ss(mass_factor: float) -> StateSpace:
    """An acceleration-like loop: a 30 Hz, ζ 0.7 mode (natural frequency 1/√
    ``mass_factor``) behind a second-order high-pass at 0.5 Hz (ζ 0.7), as an
    AC-coupled sensor or a shaking table's acceleration generator puts one in the loop."""
    wn, wh = 2 * math.pi * 30.0 / math.sqrt(mass_factor), 2 * math.pi * 0.5
    num = np.polymul([wn**2], [1.0, 0.0, 0.0])
    den = np.polymul([1.0, 1.4 * wn, wn**2], [1.0, 1.4 * wh, wh**2])
    return StateSpace(*tf2ss(num, den))


def _delayed_ss(mass_factor: float) -> StateSpace:
    """A 12 Hz, ζ 0.5 position loop (a mass on the loop's stiffness and damping: its
    moving mass × ``mass_factor``) behind 2 ms of delay (third-order Padé), as the
    loopback target of the UDP tests runs one."""
    w = 2 * math.pi * 12.0
    num_d, den_d = control.pade(0.002, 3)
    num = np.polymul([w * w], num_d)
    den = np.polymul([mass_factor, 2 * 0.5 * w, w * w], den_d)
    return StateSpace(*tf2ss(num, den))


def _oil_column_ss(mass_factor: float) -> StateSpace:
    """A 15 Hz, ζ 0.7 position loop in series with the oil column's mode (40 Hz, ζ 0.15),
    both natural frequencies 1/√ ``mass_factor``: a heavier payload on the same column."""
    w = 2 * math.pi * 15.0 / math.sqrt(mass_factor)
    o = 2 * math.pi * 40.0 / math.sqrt(mass_factor)
    den = np.polymul([1.0, 1.4 * w, w * w], [1.0, 0.3 * o, o * o])
    return StateSpace(*tf2ss([w * w * o * o], den))


def _lagged_ss(mass_factor: float) -> StateSpace:
    """An 8 Hz, ζ 0.6 position loop (its natural frequency 1/√ ``mass_factor``) behind
    a first-order lag at 30 Hz (a valve's)."""
    w = 2 * math.pi * 8.0 / math.sqrt(mass_factor)
    p = 2 * math.pi * 30.0
    return StateSpace(*tf2ss([w * w * p], np.polymul([1.0, 1.2 * w, w * w], [1.0, p])))


def _record(make, fs: float, *, n_channels: int, duration_s: float, seed: int,
            rms: float, band_hz: tuple[float, float], change_s: float | None,
            factor: float, channel: int, noise: float = 0.01,
            gain: np.ndarray | None = None):
    layout = rig_layout(n_channels)
    n = int(round(duration_s * fs))
    out = np.empty((n, layout.n_fields))
    out[:, 0] = np.arange(n) / fs
    cut = n if change_s is None else int(round(change_s * fs))
    for k in range(1, n_channels + 1):
        r = reference(n, fs, band_hz, rms, seed + k)
        if gain is not None:
            r = r * gain
        y = np.empty(n)
        state = None
        for scale, (a, b) in ((1.0, (0, cut)),
                              (factor if k == channel else 1.0, (cut, n))):
            if b <= a:
                continue
            ad, bd, cd = discrete(make, scale, fs)
            x0 = np.zeros(ad.shape[0]) if state is None else state
            state = simulate_states(ad, bd, cd, r[a:b], x0, y[a:b])
        noise_rng = np.random.default_rng(seed + 1000 + k)
        y_rms = float(np.sqrt(np.mean(y[:cut] ** 2)))
        out[:, layout.ref_index[k - 1]] = r
        out[:, layout.fb_index[k - 1]] = y + noise * y_rms * noise_rng.standard_normal(n)
    return layout, out, fs


@njit(cache=True)
def simulate_states(a, b, c, u, x0, y):
    """x(k+1) = A x(k) + B u(k), y(k) = C x(k) from x(0) = x0 into ``y``; returns the
    state after the last sample."""
    n = x0.size
    x = x0.copy()
    nxt = np.empty(n)
    for k in range(u.size):
        acc = 0.0
        for i in range(n):
            acc += c[i] * x[i]
        y[k] = acc
        for i in range(n):
            acc = b[i] * u[k]
            for j in range(n):
                acc += a[i, j] * x[j]
            nxt[i] = acc
        x[:] = nxt
    return x


def reference(n: int, fs: float, band_hz: tuple[float, float], rms: float,
               seed: int) -> np.ndarray:
    """Gaussian noise through a 4th-order Butterworth band-pass, scaled to ``rms`` and
    faded in over 0.2 s (O(n): a 10-minute record at 4 kHz in milliseconds)."""
    sos = butter(4, band_hz, btype="bandpass", fs=fs, output="sos")
    r = sosfilt(sos, np.random.default_rng(seed).standard_normal(n))
    r *= rms / np.sqrt(np.mean(r**2))
    m = min(n, int(0.2 * fs))
    r[:m] *= 0.5 - 0.5 * np.cos(np.pi * np.arange(m) / m)
    return r


def discrete(make: Callable[[float], StateSpace], factor: float, fs: float
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``make(factor)`` held over each sample (zero-order hold) at ``fs``: A (contiguous),
    B and C as vectors, as :func:`simulate_states` takes them."""
    ss = make(factor)
    ad, bd, cd, _, _ = cont2discrete((ss.A, ss.B, ss.C, ss.D), 1 / fs, method="zoh")
    return np.ascontiguousarray(ad), bd[:, 0].copy(), cd[0].copy()


def _servo_mass(mass_factor: float) -> StateSpace:
    """The servo with its moving mass × ``mass_factor`` (natural frequency 1/√ that)."""
    return _servo_ss(1 / math.sqrt(mass_factor))


@dataclass(frozen=True)
class LoopSpec:
    """One loop of this module: ``make(factor)``, its closed-loop state space with one
    physical parameter (``parameter``) × ``factor``; its rate; its reference's RMS and
    band."""

    name: str
    make: Callable[[float], StateSpace]
    fs: float
    rms: float
    band_hz: tuple[float, float]
    parameter: str


#: The 25 Hz servo at 2 kHz; its factor scales the moving mass.
SERVO = LoopSpec("servo", _servo_mass, 2000.0, 1e-3, (1.0, 60.0), "mass")
#: The actuator on its specimen at 4 kHz; its factor scales the specimen's stiffness.
SPECIMEN = LoopSpec("specimen", _specimen_ss, 4000.0, 1e-3, (1.0, 100.0), "stiffness")
#: The loop behind a 0.5 Hz high-pass at 1 kHz; its factor scales the moving mass.
HIGH_PASS = LoopSpec("high-pass", _high_pass_ss, 1000.0, 1e-3, (1.0, 40.0), "mass")
#: The 12 Hz loop behind 2 ms of delay at 1 kHz; its factor scales the moving mass.
DELAYED = LoopSpec("delayed", _delayed_ss, 1000.0, 1e-3, (0.5, 20.0), "mass")
#: The 15 Hz loop with its 40 Hz oil-column mode at 2 kHz; its factor scales the mass.
OIL_COLUMN = LoopSpec("oil-column", _oil_column_ss, 2000.0, 1e-3, (1.0, 50.0), "mass")
#: The 8 Hz loop behind a 30 Hz lag at 1 kHz; its factor scales the moving mass.
LAGGED = LoopSpec("lagged", _lagged_ss, 1000.0, 1e-3, (0.5, 15.0), "mass")


def servo_record(*, n_channels: int = 2, duration_s: float, seed: int,
                 change_s: float | None = None, mass_factor: float = 1.0,
                 channel: int = 1):
    """The 25 Hz servo at 2 kHz; from ``change_s`` the moving mass of ``channel`` is
    ``mass_factor`` times larger (its natural frequency 1/√ that)."""
    return _record(SERVO.make, SERVO.fs, n_channels=n_channels, duration_s=duration_s,
                   seed=seed, rms=SERVO.rms, band_hz=SERVO.band_hz, change_s=change_s,
                   factor=mass_factor, channel=channel)


def specimen_record(*, n_channels: int = 2, duration_s: float, seed: int,
                    change_s: float | None = None, stiffness_factor: float = 1.0,
                    channel: int = 1):
    """The actuator on its specimen at 4 kHz; from ``change_s`` the specimen of
    ``channel`` is ``stiffness_factor`` times stiffer."""
    return _record(SPECIMEN.make, SPECIMEN.fs, n_channels=n_channels,
                   duration_s=duration_s, seed=seed, rms=SPECIMEN.rms,
                   band_hz=SPECIMEN.band_hz, change_s=change_s, factor=stiffness_factor,
                   channel=channel)


def loop_record(spec: LoopSpec, *, n_channels: int = 2, duration_s: float, seed: int,
                change_s: float | None = None, factor: float = 1.0, channel: int = 1,
                gain: np.ndarray | None = None):
    """Any loop of this module (``spec``) with its reference (times ``gain``, sample
    by sample, if given: a test level that steps); from ``change_s`` the parameter of
    ``channel`` is ``factor`` times what it was."""
    return _record(spec.make, spec.fs, n_channels=n_channels, duration_s=duration_s,
                   seed=seed, rms=spec.rms, band_hz=spec.band_hz, change_s=change_s,
                   factor=factor, channel=channel, gain=gain)
