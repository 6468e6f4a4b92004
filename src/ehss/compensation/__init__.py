"""Feed-forward inverse-model compensation of identified closed loops (ZPETC, ZMETC)."""

from __future__ import annotations

from ehss.compensation.apply import compensate, reference_rate
from ehss.compensation.demo import CompensationDemo, demonstrate, plot_demo, write_demo_report
from ehss.compensation.inverse import (
    METHODS,
    InverseModel,
    band_taper,
    design_inverse,
    design_inverse_tf,
    zmetc_phase,
    zpetc_magnitude,
)
from ehss.compensation.refine import DriveUpdate, RefineResult, refine, update_drive

__all__ = [
    "compensate",
    "CompensationDemo",
    "demonstrate",
    "plot_demo",
    "write_demo_report",
    "RefineResult",
    "refine",
    "DriveUpdate",
    "update_drive",
    "reference_rate",
    "METHODS",
    "InverseModel",
    "band_taper",
    "design_inverse",
    "design_inverse_tf",
    "zmetc_phase",
    "zpetc_magnitude",
]
