"""Candidate parameter sets (the `params` option)."""

import pytest

from jaxcal import DataError, preset
from jaxcal.calibration import parse_params


def test_parse_params():
    r = preset("panda")
    names = [c.name for c in parse_params("auto", r)]
    assert names[0] == "frames" and names[-1] == "all" and "offsets" in names
    (c,) = parse_params("theta,a4", r)
    assert c.dh == tuple(sorted([4 * j for j in range(7)] + [4 * 3 + 2]))
    (c,) = parse_params("offsets", r, ridge_mm=2.0)
    assert c.ridge_mm == 2.0 and c.dh == tuple(4 * j for j in range(7))
    with pytest.raises(DataError, match="unknown parameter or set 'beta'"):
        parse_params("theta,beta", r)
    with pytest.raises(DataError, match="unknown parameter or set 'theta9'"):
        parse_params("theta9", r)


def test_ridge_weights_are_one_over_mm_and_mrad():
    """A ridge of s means s mm for the lengths d, a and s mrad for the angles theta, alpha."""
    r = preset("panda")
    (c,) = parse_params("all", r, ridge_mm=2.0)
    assert [c.prior_weight(4 * 3 + k) for k in range(4)] == pytest.approx([500.0, 0.5, 0.5, 500.0])
    (free,) = parse_params("all", r)
    assert free.prior_weight(5) == 0.0
