"""The paper's experimental programme end to end, and its report (``ehss reproduce``)."""

from __future__ import annotations

from ehss.report.paper_models import PRINTED_MODELS, PrintedModel, printed_model_findings
from ehss.report.programme import (
    DEFAULT_SETUPS,
    LoopResult,
    LoopSetup,
    ProgrammeResult,
    ProgrammeSettings,
    run_programme,
)
from ehss.report.render import summary_dict, write_report

__all__ = [
    "PRINTED_MODELS",
    "PrintedModel",
    "printed_model_findings",
    "DEFAULT_SETUPS",
    "LoopResult",
    "LoopSetup",
    "ProgrammeResult",
    "ProgrammeSettings",
    "run_programme",
    "summary_dict",
    "write_report",
]
