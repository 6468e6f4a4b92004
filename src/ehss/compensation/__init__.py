"""Feed-forward inverse-model compensation of identified closed loops.

:mod:`~ehss.compensation.inverse` designs the inverse (exact stable inversion by default,
ZPETC and ZMETC as options) inside the band the model was validated over, and
:mod:`~ehss.compensation.inverse_model` holds it and applies it to a reference;
:mod:`~ehss.compensation.apply` computes a drive file from it (at the model's rate or,
through :mod:`~ehss.compensation.rates`, at an integer multiple of it: a model identified
from a decimated record drives the rig at the record's rate); :mod:`~ehss.compensation.checks`
refuses drives that would exceed a sane gain or the rig's limits; and
:mod:`~ehss.compensation.iteration` corrects a drive from a measured run (model-based or
from the measured frequency response), refusing updates that make the error grow.
Experiments on the simulated rig live in :mod:`ehss.experiments`.
"""

from __future__ import annotations

from ehss.compensation.apply import (
    OUTSIDE_BAND,
    OUTSIDE_SHARE_WARN,
    Compensation,
    apply_inverse,
    as_reference,
    compensate,
    compensation,
    model_offsets,
    outside_band_note,
    warn_if_outside_band,
)
from ehss.compensation.checks import (
    DEFAULT_MAX_GAIN,
    DEFAULT_MIN_GAIN,
    REST_TOLERANCE,
    DriveCheck,
    DriveLimits,
    check_at_rest,
    check_drive,
    check_rig,
    checked_drive,
    fade_to_rest,
)
from ehss.compensation.inverse import (
    CIRCLE_MARGIN,
    METHODS,
    InverseModel,
    band_taper,
    design_inverse,
    design_inverse_tf,
    zmetc_phase,
    zpetc_magnitude,
)
from ehss.compensation.iteration import (
    UPDATE_METHODS,
    DriveUpdate,
    IterationState,
    RunRecord,
    UpdateOptions,
    corrected_drive,
    lag_samples,
    learning_gain,
    run_record,
    update_drive,
)

__all__ = [
    "compensate",
    "compensation",
    "Compensation",
    "model_offsets",
    "outside_band_note",
    "DEFAULT_MIN_GAIN",
    "check_rig",
    "checked_drive",
    "apply_inverse",
    "warn_if_outside_band",
    "OUTSIDE_SHARE_WARN",
    "OUTSIDE_BAND",
    "as_reference",
    "DEFAULT_MAX_GAIN",
    "REST_TOLERANCE",
    "DriveCheck",
    "DriveLimits",
    "check_at_rest",
    "check_drive",
    "fade_to_rest",
    "CIRCLE_MARGIN",
    "METHODS",
    "InverseModel",
    "band_taper",
    "design_inverse",
    "design_inverse_tf",
    "zmetc_phase",
    "zpetc_magnitude",
    "UPDATE_METHODS",
    "corrected_drive",
    "DriveUpdate",
    "IterationState",
    "RunRecord",
    "lag_samples",
    "learning_gain",
    "run_record",
    "update_drive",
    "UpdateOptions",
]
