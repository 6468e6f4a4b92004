"""Experiments on the simulated rig: whole programmes built on the library below.

The library (params → plant → control → simulation → identification → validation →
compensation) knows nothing of a particular experiment; this layer runs them: the
paper's programme behind the report, the compensation demonstration and drive-file
refinement on the simulated rig.
"""

from __future__ import annotations

__all__: list[str] = []
