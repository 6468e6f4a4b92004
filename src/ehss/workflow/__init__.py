"""One identification workflow, from a measured record to a validated model and a verdict.

``ehss identify``, ``ehss order`` and the report all go through these functions, so a
model "meets the acceptance" in one sense only, the one :class:`Acceptance` defines, and
their settings are the same objects everywhere (:mod:`ehss.workflow.options`):
:class:`Preparation`, :class:`Estimation`, :class:`Evaluation` and :class:`OrderGrid`.

1. :func:`prepare` splits the record into estimation and validation data (the held-out
   end, or a separate record), removes the operating point or a drift from each
   (:func:`ehss.preprocess.detrend`) and decimates an oversampled record
   (:func:`ehss.preprocess.decimate`, factor from :func:`ehss.preprocess.auto_decimation`);
2. :func:`identify` fits the model with :func:`ehss.identification.estimate`, validates it
   on the validation data (:func:`assess`, which serves models made otherwise too;
   :func:`ehss.validation.validate`: free-run fit from the
   least-squares initial state, k-step prediction fit, frequency-response error where the
   coherence is high, residual tests) and judges it with :meth:`Acceptance.judge`;
3. :func:`select_orders` prepares the record once as :func:`identify` does, fits every
   candidate of a grid of orders with the same estimator and ranks them by the same
   validation (:func:`assess`), so its pick validates the same when :func:`identify`
   refits it.

The model comes back with its operating point (``offsets``) and with ``band_hz`` set to
the span of frequencies over which the validation compared it with the data
(:func:`validated_band`: from DC when the comparison held from the estimate's first
bin). A decimated record gives a model at the decimated rate (its ``dt`` says so, and so
does :meth:`Identification.format`); :func:`ehss.compensate` applies it at the record's
rate.

Modules: :mod:`~ehss.workflow.options` (the settings), :mod:`~ehss.workflow.acceptance`,
:mod:`~ehss.workflow.preparing`, :mod:`~ehss.workflow.identifying`,
:mod:`~ehss.workflow.orders`.
"""

from __future__ import annotations

from ehss.workflow.acceptance import Acceptance, Verdict
from ehss.workflow.identifying import (
    Identification,
    assess,
    delay_text,
    identify,
    validated_band,
)
from ehss.workflow.options import (
    CRITERIA,
    DEFAULT_METHOD,
    ERROR_TOLERANCE,
    SAMPLES_PER_PARAMETER,
    Estimation,
    Evaluation,
    OrderGrid,
    Preparation,
)
from ehss.workflow.orders import OrderSearch, select_orders
from ehss.workflow.preparing import HOLDOUT_EXCITATION_WARN, Prepared, judged_band, prepare

__all__ = [
    "Acceptance",
    "Verdict",
    "Preparation",
    "Estimation",
    "Evaluation",
    "OrderGrid",
    "Prepared",
    "Identification",
    "DEFAULT_METHOD",
    "CRITERIA",
    "prepare",
    "identify",
    "assess",
    "OrderSearch",
    "select_orders",
    "validated_band",
    "judged_band",
    "delay_text",
    "HOLDOUT_EXCITATION_WARN",
    "SAMPLES_PER_PARAMETER",
    "ERROR_TOLERANCE",
]
