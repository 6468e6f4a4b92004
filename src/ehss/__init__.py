"""ehss: electro-hydraulic servo systems in Python.

Simulate a hydraulic shaking table / loading rig, close its position, acceleration and
force loops, identify the closed-loop transfer functions online with recursive extended
least squares (RELS), validate them against non-parametric frequency responses and use
them for feed-forward compensation.

The layout follows the architecture: :mod:`ehss.params` and :mod:`ehss.plant` (the rig),
:mod:`ehss.control` (controllers and tunings), :mod:`ehss.linear` (the paper's transfer
functions), :mod:`ehss.simulation` (closed loops), :mod:`ehss.signals` (tests),
:mod:`ehss.identification` (RELS and ARMAX models), :mod:`ehss.frequency` and
:mod:`ehss.validation` (H1 estimates and model checks), :mod:`ehss.compensation`
(feed-forward inverses), :mod:`ehss.report` and :mod:`ehss.cli`. Plots live in
:mod:`ehss.plots` and are not imported here, so ``import ehss`` does not load matplotlib's
pyplot.
"""

from __future__ import annotations

from importlib.metadata import PackageNotFoundError, version

from ehss import signals
from ehss.compensation import InverseModel, compensate, design_inverse
from ehss.errors import DataError, EhssError, EhssWarning, IdentificationError, ParameterError
from ehss.experiments.compensation_demo import CompensationDemo, demonstrate
from ehss.experiments.refinement import refine
from ehss.frequency import FrequencyResponse, h1_estimate
from ehss.identification import (
    ArmaxModel,
    OrderSelection,
    RelsEstimator,
    armax_els,
    arx_ls,
    rels,
    select_order,
)
from ehss.io import Table, read_columns, sample_rate, write_csv, write_json
from ehss.params import RigParams, load_params, preset, save_params
from ehss.plant import simulate_open_loop
from ehss.signals import Signal, check_feasible
from ehss.simulation import SimulationResult, simulate
from ehss.validation import (
    FrfError,
    ResidualTests,
    ValidationReport,
    frf_error,
    nrmse_fit,
    prediction_fit,
    residual_tests,
    simulation_fit,
    validate,
)

# python-control (and with it pyplot) loads only when its part of ehss is used.
_LAZY = {
    "linear": ("ehss.linear", None),
    "tune_position": ("ehss.control.tuning", "tune_position"),
    "tune_tvc": ("ehss.control.tuning", "tune_tvc"),
    "tune_force": ("ehss.control.tuning", "tune_force"),
}


def __getattr__(name: str):
    if name in _LAZY:
        import importlib

        module_name, attr = _LAZY[name]
        module = importlib.import_module(module_name)
        return module if attr is None else getattr(module, attr)
    raise AttributeError(f"module 'ehss' has no attribute {name!r}")


try:
    __version__ = version("ehss")
except PackageNotFoundError:  # pragma: no cover - running from a source tree
    __version__ = "0.0.0+unknown"

__all__ = [
    "__version__",
    # errors
    "EhssError",
    "ParameterError",
    "DataError",
    "IdentificationError",
    "EhssWarning",
    # rig and controllers
    "RigParams",
    "preset",
    "load_params",
    "save_params",
    "tune_position",
    "tune_tvc",
    "tune_force",
    "linear",
    # simulation and signals
    "simulate",
    "SimulationResult",
    "simulate_open_loop",
    "signals",
    "Signal",
    "check_feasible",
    # identification
    "ArmaxModel",
    "RelsEstimator",
    "rels",
    "arx_ls",
    "armax_els",
    "select_order",
    "OrderSelection",
    # frequency response and validation
    "FrequencyResponse",
    "h1_estimate",
    "FrfError",
    "ResidualTests",
    "ValidationReport",
    "frf_error",
    "nrmse_fit",
    "prediction_fit",
    "residual_tests",
    "simulation_fit",
    "validate",
    # compensation
    "compensate",
    "design_inverse",
    "InverseModel",
    "refine",
    "demonstrate",
    "CompensationDemo",
    # files
    "Table",
    "read_columns",
    "sample_rate",
    "write_csv",
    "write_json",
]
