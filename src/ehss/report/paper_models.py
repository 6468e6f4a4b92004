"""The closed-loop models printed in the paper, eqs (23)–(25), and what is wrong with them.

The paper prints its identified discrete transfer functions rounded to four significant
digits, with numerator and denominator of equal degree (direct feed-through, b0 ≠ 0).
Read literally, all three are unstable (largest pole radius 1.041, 1.191 and 1.249), and
for eqs (24)/(25) the rounding error alone exceeds |A(e^{jθ})| at low frequency
(PAPER.md §5). They are reproduced here only to be compared with, never as plants.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["PrintedModel", "PRINTED_MODELS", "printed_model_findings"]


@dataclass(frozen=True, kw_only=True)
class PrintedModel:
    """A transfer function as printed: G(z) = num(z)/den(z), descending powers of z."""

    equation: str
    loop: str
    num: tuple[float, ...]
    den: tuple[float, ...]

    @property
    def poles(self) -> np.ndarray:
        return np.roots(self.den)

    @property
    def max_pole_radius(self) -> float:
        return float(np.max(np.abs(self.poles)))

    @property
    def is_stable(self) -> bool:
        return self.max_pole_radius < 1.0

    def format(self) -> str:
        """The printed form, e.g. ``(0.02122 z^4 - ...) / (z^4 - 3.457 z^3 + ...)``."""
        return f"({_poly(self.num)}) / ({_poly(self.den)})"


def _poly(coeffs: tuple[float, ...]) -> str:
    n = len(coeffs) - 1
    terms = []
    for i, c in enumerate(coeffs):
        power = n - i
        z = "" if power == 0 else ("z" if power == 1 else f"z^{power}")
        mag = f"{abs(c):.10g}"
        body = z if (mag == "1" and z) else (f"{mag} {z}".strip())
        sign = "-" if c < 0 else "+"
        terms.append((sign, body))
    first_sign, first = terms[0]
    text = ("-" if first_sign == "-" else "") + first
    for sign, body in terms[1:]:
        text += f" {sign} {body}"
    return text


# Signs restored from the garbled extraction (a lost minus shows as a double space);
# the pole radii below match PAPER.md §5 (1.041, 1.191, 1.249).
PRINTED_MODELS: dict[str, PrintedModel] = {
    "position": PrintedModel(
        equation="(23)",
        loop="position",
        num=(0.02122, -0.0922, 0.1616, -0.1324, 0.04571),
        den=(1.0, -3.457, 4.825, -3.165, 0.8187),
    ),
    "acceleration": PrintedModel(
        equation="(24)",
        loop="acceleration",
        num=(0.007585, 0.05972, -0.1888, 0.3441, -0.3756, 0.2271, -0.05796),
        den=(1.0, -5.342, 12.25, -15.43, 11.24, -4.484, 0.7637),
    ),
    "force": PrintedModel(
        equation="(25)",
        loop="force",
        num=(0.09572, -0.5944, 1.567, -2.235, 1.812, -0.7909, 0.1451),
        den=(1.0, -5.382, 12.17, -14.79, 10.19, -3.769, 0.5849),
    ),
}


def printed_model_findings() -> dict[str, dict[str, object]]:
    """Stability of each printed model, as plain values for a report."""
    out: dict[str, dict[str, object]] = {}
    for loop, m in PRINTED_MODELS.items():
        out[loop] = {
            "equation": m.equation,
            "printed": m.format(),
            "max_pole_radius": m.max_pole_radius,
            "stable": m.is_stable,
            "direct_feedthrough": m.num[0] != 0.0,
        }
    return out
