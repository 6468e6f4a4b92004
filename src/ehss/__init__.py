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
:mod:`ehss.plots`.

``import ehss`` is light: each public name below is imported on first use (PEP 562), so
the command line starts at once and answers Ctrl-C during start-up with one line.
"""

from __future__ import annotations

import importlib

TYPE_CHECKING = False  # typing itself imports re: keep ``import ehss`` light

# Public name -> module that defines it (a module itself when the name is a module).
_LAZY = {
    # errors
    "EhssError": "ehss.errors",
    "ParameterError": "ehss.errors",
    "DataError": "ehss.errors",
    "IdentificationError": "ehss.errors",
    "EhssWarning": "ehss.errors",
    # rig and controllers
    "RigParams": "ehss.params",
    "preset": "ehss.params",
    "load_params": "ehss.params",
    "save_params": "ehss.params",
    "tune_position": "ehss.control.tuning",
    "tune_tvc": "ehss.control.tuning",
    "tune_force": "ehss.control.tuning",
    "linear": None,
    # simulation and signals
    "simulate": "ehss.simulation",
    "SimulationResult": "ehss.simulation",
    "simulate_open_loop": "ehss.simulation",
    "signals": None,
    "Signal": "ehss.signals",
    "check_feasible": "ehss.signals",
    # identification
    "ArmaxModel": "ehss.identification",
    "RelsEstimator": "ehss.identification",
    "rels": "ehss.identification",
    "arx_ls": "ehss.identification",
    "armax_els": "ehss.identification",
    "select_order": "ehss.identification",
    "OrderSelection": "ehss.identification",
    "estimate": "ehss.identification",
    # the identification workflow: prepare, estimate, validate, judge
    "identify": "ehss.workflow",
    "Identification": "ehss.workflow",
    "Acceptance": "ehss.workflow",
    "assess": "ehss.workflow",
    "prepare": "ehss.workflow",
    "select_orders": "ehss.workflow",
    "OrderSearch": "ehss.workflow",
    "Preparation": "ehss.workflow",
    "Estimation": "ehss.workflow",
    "Evaluation": "ehss.workflow",
    "OrderGrid": "ehss.workflow",
    "preprocess": None,
    "workflow": None,
    # frequency response and validation
    "FrequencyResponse": "ehss.frequency",
    "h1_estimate": "ehss.frequency",
    "FrfError": "ehss.validation",
    "ResidualTests": "ehss.validation",
    "ValidationReport": "ehss.validation",
    "frf_error": "ehss.validation",
    "nrmse_fit": "ehss.validation",
    "prediction_fit": "ehss.validation",
    "residual_tests": "ehss.validation",
    "simulation_fit": "ehss.validation",
    "validate": "ehss.validation",
    # compensation
    "compensate": "ehss.compensation",
    "design_inverse": "ehss.compensation",
    "InverseModel": "ehss.compensation",
    "UpdateOptions": "ehss.compensation",
    "refine": "ehss.experiments.refinement",
    "demonstrate": "ehss.experiments.compensation_demo",
    "CompensationDemo": "ehss.experiments.compensation_demo",
    # files
    "Table": "ehss.io",
    "read_columns": "ehss.io",
    "sample_rate": "ehss.io",
    "write_csv": "ehss.io",
    "write_table": "ehss.io",
    "read_metadata": "ehss.io",
    "write_json": "ehss.io",
    # numba kernels compiled ahead of use
    "warm_up": "ehss._warm",
}

if TYPE_CHECKING:  # what the lazy names are, for type checkers and editors
    from typing import Any

    from ehss import linear, preprocess, signals, workflow
    from ehss._warm import warm_up
    from ehss.compensation import InverseModel, UpdateOptions, compensate, design_inverse
    from ehss.control.tuning import tune_force, tune_position, tune_tvc
    from ehss.errors import (
        DataError,
        EhssError,
        EhssWarning,
        IdentificationError,
        ParameterError,
    )
    from ehss.experiments.compensation_demo import CompensationDemo, demonstrate
    from ehss.experiments.refinement import refine
    from ehss.frequency import FrequencyResponse, h1_estimate
    from ehss.identification import (
        ArmaxModel,
        OrderSelection,
        RelsEstimator,
        armax_els,
        arx_ls,
        estimate,
        rels,
        select_order,
    )
    from ehss.io import (
        Table,
        read_columns,
        read_metadata,
        sample_rate,
        write_csv,
        write_json,
        write_table,
    )
    from ehss.params import RigParams, load_params, preset, save_params
    from ehss.signals import Signal, check_feasible
    from ehss.simulation import SimulationResult, simulate, simulate_open_loop
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
    from ehss.workflow import (
        Acceptance,
        Estimation,
        Evaluation,
        Identification,
        OrderGrid,
        OrderSearch,
        Preparation,
        assess,
        identify,
        prepare,
        select_orders,
    )


def __getattr__(name: str) -> Any:
    """Import a public name on first use (PEP 562) and keep it in the module."""
    if name == "__version__":
        from importlib.metadata import PackageNotFoundError, version

        try:
            text = version("ehss")
        except PackageNotFoundError:  # pragma: no cover - running from a source tree
            text = "0.0.0+unknown"
        globals()[name] = text
        return text
    try:
        module_name = _LAZY[name]
    except KeyError:
        raise AttributeError(f"module 'ehss' has no attribute {name!r}") from None
    if module_name is None:
        value = importlib.import_module(f"ehss.{name}")
    else:
        value = getattr(importlib.import_module(module_name), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY))


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
    "estimate",
    "identify",
    "Identification",
    "Acceptance",
    "assess",
    "prepare",
    "select_orders",
    "OrderSearch",
    "Preparation",
    "Estimation",
    "Evaluation",
    "OrderGrid",
    "preprocess",
    "workflow",
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
    "UpdateOptions",
    "refine",
    "demonstrate",
    "CompensationDemo",
    # files
    "Table",
    "read_columns",
    "sample_rate",
    "write_csv",
    "write_table",
    "read_metadata",
    "write_json",
    # numba kernels compiled ahead of use
    "warm_up",
]
