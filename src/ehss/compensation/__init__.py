"""Feed-forward inverse-model compensation of identified closed loops (ZPETC, ZMETC)."""

from __future__ import annotations

from ehss.compensation.apply import compensate, reference_rate
from ehss.compensation.inverse import (
    METHODS,
    InverseModel,
    band_taper,
    design_inverse,
    design_inverse_tf,
    zmetc_phase,
    zpetc_magnitude,
)

__all__ = [
    "compensate",
    "reference_rate",
    "METHODS",
    "InverseModel",
    "band_taper",
    "design_inverse",
    "design_inverse_tf",
    "zmetc_phase",
    "zpetc_magnitude",
]
