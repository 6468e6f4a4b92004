"""Loops other than the simulated rig as targets of adaptive compensation, run block by
block as :class:`ehss.live.rig.SteppingRig` runs the rig.

Each channel is one of the linear loops of ``loops_for_detection.py`` (the 25 Hz servo
at 2 kHz, the actuator on its specimen at 4 kHz: :data:`SERVO`, :data:`SPECIMEN`), its
drive made online from the desired reference by the target's
:class:`ehss.target.filter.CompensatorFilter`, which reads the reference ``preview``
samples ahead; until a compensator is loaded the drive is the reference. The feedback
carries white sensor noise of 1 % of the channel's reference RMS (seed per channel).
From ``change_s`` on, one channel's physical parameter (the servo's mass, the
specimen's stiffness) is ``factor`` times what it was, the state carried over.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from loops_for_detection import (
    DELAYED,
    HIGH_PASS,
    LAGGED,
    OIL_COLUMN,
    SERVO,
    SPECIMEN,
    LoopSpec,
    discrete,
    simulate_states,
)

import ehss
from ehss.target.filter import Compensator, CompensatorFilter

__all__ = ["SteppingLoop", "LoopBlock", "loop_desired", "SERVO", "SPECIMEN", "HIGH_PASS",
           "DELAYED", "OIL_COLUMN", "LAGGED"]


def loop_desired(spec: LoopSpec, duration_s: float, seeds: tuple[int, ...], *,
                 band_hz: tuple[float, float] | None = None) -> np.ndarray:
    """One desired reference per seed for ``spec``'s loop, shape (len(seeds), n): flat
    within ``band_hz`` (default its band), nothing outside
    (:func:`ehss.signals.band_limited_random`), its RMS, faded in and out over 0.2 s."""
    return np.vstack([
        ehss.signals.band_limited_random(band_hz=band_hz or spec.band_hz, rms=spec.rms,
                                         duration_s=duration_s, fs=spec.fs, seed=seed,
                                         fade_s=0.2).values
        for seed in seeds])


@dataclass(frozen=True)
class LoopBlock:
    """Consecutive samples of every channel, each shape (n_channels, n): the desired
    reference, the drive the loop received and the measured feedback."""

    first_index: int
    desired: np.ndarray
    drive: np.ndarray
    feedback: np.ndarray


class SteppingLoop:
    """N channels of one linear loop, stepped block by block (the ``Target`` protocol
    of :mod:`ehss.live.compensate`).

    Parameters
    ----------
    spec : LoopSpec
    desired : ndarray, shape (n_channels, n)
    preview : int
        Samples of reference each filter reads ahead.
    seed : int
        Channel k's sensor noise has seed ``seed + 1000 + k``.
    change_s : float, optional
        When ``channel``'s parameter becomes ``factor`` × what it was (None: never).
    factor : float
    channel : int
        1-based.
    noise : float
        Sensor noise RMS as a fraction of the channel's reference RMS.
    """

    def __init__(self, spec: LoopSpec, desired: np.ndarray, *, preview: int, seed: int = 0,
                 change_s: float | None = None, factor: float = 1.0, channel: int = 1,
                 noise: float = 0.01) -> None:
        self.desired = np.atleast_2d(np.asarray(desired, dtype=float))
        self.n_channels, self.n_samples = self.desired.shape
        self.fs = float(spec.fs)
        self.channels = tuple(str(k) for k in range(1, self.n_channels + 1))
        self.preview = int(preview)
        self.index = 0
        self._systems = {1.0: discrete(spec.make, 1.0, self.fs),
                         factor: discrete(spec.make, factor, self.fs)}
        self._factor, self._channel = factor, channel
        self._cut = self.n_samples if change_s is None else int(round(change_s * self.fs))
        self._states = [np.zeros(self._systems[1.0][0].shape[0])
                        for _ in range(self.n_channels)]
        self._noise = noise * np.sqrt(np.mean(self.desired**2, axis=1))
        self._rngs = [np.random.default_rng(seed + 1000 + k)
                      for k in range(1, self.n_channels + 1)]
        self.filters = [CompensatorFilter(Compensator.delay(self.preview, fs_hz=self.fs))
                        for _ in range(self.n_channels)]
        # the filters read the first `preview` samples before the first drive sample
        for ch, f in enumerate(self.filters):
            f.process(self.desired[ch, :min(self.preview, self.n_samples)])

    @property
    def finished(self) -> bool:
        return self.index >= self.n_samples

    def load(self, channel: int, compensator: Any, apply_index: int, crossfade: int) -> bool:
        """Hand a compensator to channel ``channel``'s filter from drive sample
        ``apply_index`` on."""
        return self.filters[channel].load(compensator, apply_index + self.preview, crossfade)

    def _system(self, ch: int, k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        changed = ch + 1 == self._channel and k >= self._cut
        return self._systems[self._factor if changed else 1.0]

    def step(self, n: int) -> LoopBlock:
        """Run the next ``n`` samples (fewer at the end); the change applies at its
        sample."""
        a = self.index
        b = min(self.n_samples, a + int(n))
        drive = np.empty((self.n_channels, b - a))
        fb = np.empty((self.n_channels, b - a))
        ahead = np.minimum(np.arange(a, b) + self.preview, self.n_samples - 1)
        for ch in range(self.n_channels):
            drive[ch] = self.filters[ch].process(self.desired[ch, ahead])
            bounds = [a, *([self._cut] if a < self._cut < b else []), b]
            for lo, hi in zip(bounds[:-1], bounds[1:], strict=True):
                ad, bd, cd = self._system(ch, lo)
                self._states[ch] = simulate_states(ad, bd, cd, drive[ch, lo - a:hi - a],
                                                   self._states[ch], fb[ch, lo - a:hi - a])
            fb[ch] += self._noise[ch] * self._rngs[ch].standard_normal(b - a)
        self.index = b
        return LoopBlock(a, self.desired[:, a:b].copy(), drive, fb)
