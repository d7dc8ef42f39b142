"""The config primitives every component validates with: each refusal names the field, the bad value and what is
valid."""
import math

import numpy as np
import pytest

from tcot_hybrid.config import require_in_range
from tcot_hybrid.errors import ConfigError


@pytest.mark.parametrize("value", [0.5, 1, 1.0, np.float32(0.25), np.int64(1)])
def test_require_in_range_takes_numbers_inside_a_half_open_interval(value):
    require_in_range("share", value, 0.0, 1.0, low_closed=False)


@pytest.mark.parametrize("value, shown", [(0.0, "0.0"), (1.5, "1.5"), (-0.1, "-0.1"), (math.nan, "nan"),
                                          (True, "True"), ("0.5", "'0.5'"), (None, "None")])
def test_require_in_range_names_field_interval_and_bad_value(value, shown):
    with pytest.raises(ConfigError) as err:
        require_in_range("jerk_scale", value, 0.0, 1.0, low_closed=False, meaning="a fraction of the robot's limit")
    msg = str(err.value)
    assert "jerk_scale" in msg and "(0, 1]" in msg and "a fraction of the robot's limit" in msg and shown in msg


def test_require_in_range_ends_open_or_closed():
    require_in_range("ncc", -1.0, -1.0, 1.0)  # closed low end
    with pytest.raises(ConfigError, match=r"\(-1, 1\]"):
        require_in_range("ncc", -1.0, -1.0, 1.0, low_closed=False)
    require_in_range("frac", 0.0, 0.0, 1.0, high_closed=False)
    with pytest.raises(ConfigError, match=r"\[0, 1\)"):
        require_in_range("frac", 1.0, 0.0, 1.0, high_closed=False)
