"""The report of the paper's programme (``ehss reproduce``): figures, Markdown and HTML.

The experiments themselves run in :mod:`ehss.experiments`; this package only renders a
:class:`~ehss.experiments.ProgrammeResult`.
"""

from __future__ import annotations

from ehss.report.paper_models import PRINTED_MODELS, PrintedModel, printed_model_findings
from ehss.report.render import compensation_file, summary_dict, write_report

__all__ = [
    "PRINTED_MODELS",
    "PrintedModel",
    "printed_model_findings",
    "summary_dict",
    "write_report",
    "compensation_file",
]
