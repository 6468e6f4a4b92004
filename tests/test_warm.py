"""ehss.warm_up: the kernels it prepares are the ones later runs call."""

from __future__ import annotations

import numpy as np
import pytest

from ehss import ParameterError, RelsEstimator, rels, simulate, warm_up
from ehss.simulation import _kernels as simulation_kernels


def test_simulation_warm_up_compiles_the_loop_a_run_calls():
    warm_up(["simulation"])
    compiled = list(simulation_kernels.closed_loop.signatures)
    assert compiled
    # another loop, length and reference: the same compiled kernel, nothing new
    simulate("force", np.full(50, 100.0), seed=1)
    simulate("acceleration", np.zeros(30), seed=2)
    assert simulation_kernels.closed_loop.signatures == compiled


def test_identification_and_streaming_warm_up_run_for_given_orders():
    # the orders reach the estimators: impossible ones are refused by them
    with pytest.raises((ParameterError, TypeError)):
        warm_up(["identification"], na=-1)
    with pytest.raises((ParameterError, TypeError)):
        warm_up(["streaming"], nb=-1)
    warm_up(["identification", "streaming"], na=2, nb=1, nc=1, delay=1)
    u = np.random.default_rng(3).standard_normal(300)
    assert np.all(np.isfinite(rels(u, u, na=2, nb=1, nc=1).theta))
    assert np.isfinite(RelsEstimator(na=2, nb=1, nc=1).update(0.1, 0.2))


@pytest.mark.parametrize("kwargs", [{"kinds": ["compile"]}, {"methods": ["ls"]}])
def test_unknown_kind_or_method_is_refused(kwargs):
    with pytest.raises(ParameterError):
        warm_up(**kwargs)


def test_specialised_warm_up_compiles_the_loop_for_those_orders():
    from ehss.identification import _kernels as rels_kernels

    warm_up(["specialised"], na=1, nb=1, nc=1, delay=2, methods=["rels"])
    assert (1, 1, 1, 2) in rels_kernels._ENTRIES  # what kernel_for then returns
