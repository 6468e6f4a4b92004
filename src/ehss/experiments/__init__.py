"""Experiments on the simulated rig: whole programmes built on the library below.

The library (params → plant → control → simulation → identification → validation →
compensation) knows nothing of a particular experiment; this layer runs them: the
paper's programme behind the report (:mod:`~ehss.experiments.programme`), its step tests
(:mod:`~ehss.experiments.steps`) and loop identifications
(:mod:`~ehss.experiments.loop_identification`), the compensation demonstration and
drive-file refinement on the simulated rig.
"""

from __future__ import annotations

from ehss.experiments.compensation_demo import (
    CompensationDemo,
    demonstrate,
    plot_demo,
    write_demo_report,
)
from ehss.experiments.loop_identification import (
    ACCEPTANCE,
    ModelCheck,
    Record,
    identify_and_check,
    loop_record,
)
from ehss.experiments.programme import (
    DEFAULT_SETUPS,
    LoopResult,
    LoopSetup,
    ProgrammeResult,
    ProgrammeSettings,
    run_programme,
)
from ehss.experiments.refinement import RefineResult, refine
from ehss.experiments.steps import StepMetrics, StepTest, step_metrics, step_tests

__all__ = [
    "CompensationDemo",
    "demonstrate",
    "plot_demo",
    "write_demo_report",
    "RefineResult",
    "refine",
    "ACCEPTANCE",
    "ModelCheck",
    "Record",
    "identify_and_check",
    "loop_record",
    "DEFAULT_SETUPS",
    "LoopResult",
    "LoopSetup",
    "ProgrammeResult",
    "ProgrammeSettings",
    "run_programme",
    "StepMetrics",
    "StepTest",
    "step_metrics",
    "step_tests",
]
