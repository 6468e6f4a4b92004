"""The programme's settings check every field when they are made."""

from __future__ import annotations

import pytest

from ehss.errors import ParameterError
from ehss.experiments.programme import DEFAULT_SETUPS, ProgrammeSettings


@pytest.mark.parametrize(("field", "value", "error"), [
    ("seed", -1, ParameterError),
    ("duration_s", 4.9, ParameterError),
    ("step_duration_s", 0.0, ParameterError),
    ("holdout", 0.7, ParameterError),
    ("forgetting", 1.5, ParameterError),
    ("p0", -1.0, ParameterError),
    ("setups", {"position": (4, 3, 2, 1)}, TypeError),
    ("order_grid", (0, 2), ParameterError),
    ("noise_orders", (-1,), ParameterError),
    ("max_search_order", 0, ParameterError),
    ("compensation", "yes", TypeError),
    ("compensation_duration_s", 3.0, ParameterError),
])
def test_a_bad_field_is_refused_by_name(field, value, error):
    with pytest.raises(error, match=field):
        ProgrammeSettings(**{field: value})


def test_the_defaults_and_given_values_are_kept():
    s = ProgrammeSettings(seed=3, duration_s=20.0, order_grid=[4, 6])
    assert (s.seed, s.duration_s, s.order_grid) == (3, 20.0, (4, 6))
    assert s.setups == DEFAULT_SETUPS and s.setups is not DEFAULT_SETUPS
    assert ProgrammeSettings().holdout == 0.3
