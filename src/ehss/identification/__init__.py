"""ARMAX models and their identification (RELS/RML, ARX, ARMAX and OE by PEM, order selection)."""

from __future__ import annotations

from ehss.identification._common import ArmaxOrders, RelsSettings
from ehss.identification.batch import armax_els, arx_ls
from ehss.identification.delay import estimate_delay
from ehss.identification.estimators import INITS, METHODS, estimate
from ehss.identification.model import ArmaxModel, RoundingSensitivity
from ehss.identification.order import OrderRow, OrderSelection, select_order
from ehss.identification.pem import armax_pem, oe_pem
from ehss.identification.rels import RelsEstimator, rels

__all__ = [
    "ArmaxModel",
    "RoundingSensitivity",
    "RelsEstimator",
    "RelsSettings",
    "ArmaxOrders",
    "rels",
    "arx_ls",
    "armax_els",
    "armax_pem",
    "oe_pem",
    "estimate",
    "METHODS",
    "INITS",
    "OrderRow",
    "OrderSelection",
    "select_order",
    "estimate_delay",
]
