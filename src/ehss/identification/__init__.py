"""ARMAX models and their identification (RELS, batch least squares, order selection)."""
