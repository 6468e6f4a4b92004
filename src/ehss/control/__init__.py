"""Digital controllers of the three loops and their default tunings."""

from __future__ import annotations

from ehss.control.discrete import (
    complementary_velocity_tustin,
    generator_zoh,
    pid_coefficients,
    tvc_coefficients,
)

__all__ = [
    "complementary_velocity_tustin",
    "generator_zoh",
    "pid_coefficients",
    "tvc_coefficients",
]
# The tunings (ehss.control.tuning) use python-control; import that module explicitly.
