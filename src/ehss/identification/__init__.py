"""ARMAX models and their identification (RELS, batch least squares, order selection)."""

from __future__ import annotations

from ehss.identification.batch import armax_els, arx_ls
from ehss.identification.estimators import METHODS, estimate
from ehss.identification.model import ArmaxModel, RoundingSensitivity
from ehss.identification.order import OrderRow, OrderSelection, select_order
from ehss.identification.rels import RelsEstimator, rels

__all__ = [
    "ArmaxModel",
    "RoundingSensitivity",
    "RelsEstimator",
    "rels",
    "arx_ls",
    "armax_els",
    "estimate",
    "METHODS",
    "OrderRow",
    "OrderSelection",
    "select_order",
]
