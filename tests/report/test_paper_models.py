from __future__ import annotations

import numpy as np
import pytest

from ehss.report.paper_models import PRINTED_MODELS, printed_model_findings


@pytest.mark.parametrize(
    ("loop", "radius"),
    # PAPER.md §5: the printed eqs (23)-(25) have max pole radius 1.041, 1.191, 1.249.
    [("position", 1.041), ("acceleration", 1.191), ("force", 1.249)],
)
def test_printed_models_are_unstable_as_documented(loop, radius):
    m = PRINTED_MODELS[loop]
    assert m.max_pole_radius == pytest.approx(radius, abs=5e-4)
    assert not m.is_stable
    assert printed_model_findings()[loop]["direct_feedthrough"] is True


def test_printed_form_round_trips_the_coefficients():
    m = PRINTED_MODELS["position"]
    text = m.format()
    assert text.startswith("(0.02122 z^4 - 0.0922 z^3")
    assert "z^4 - 3.457 z^3 + 4.825 z^2 - 3.165 z + 0.8187" in text
    # Roots and back: the same polynomial to rounding of the root finder.
    np.testing.assert_allclose(np.poly(m.poles).real, m.den, rtol=0, atol=1e-12)
