"""Candidate parameter sets (the `params` option)."""

import pytest

from jaxcal import DataError, preset
from jaxcal.calibration import parse_params


def test_parse_params():
    r = preset("panda")
    names = [c.name for c in parse_params("auto", r)]
    assert names[0] == "frames" and names[-1] == "all" and "offsets" in names and "all, prior 1 mm" in names
    (c,) = parse_params("theta,a4", r)
    assert c.dh == tuple(sorted([4 * j for j in range(7)] + [4 * 3 + 2]))
    (c,) = parse_params("offsets", r, ridge_mm=2.0)
    assert c.ridge_mm == 2.0 and c.dh == tuple(4 * j for j in range(7))
    with pytest.raises(DataError, match="unknown parameter or set 'beta'"):
        parse_params("theta,beta", r)
    with pytest.raises(DataError, match="unknown parameter or set 'theta9'"):
        parse_params("theta9", r)


def test_auto_tries_every_prior_with_and_without_compliance():
    r = preset("panda")
    names = [c.name for c in parse_params("auto", r, compliance=True)]
    assert names[:2] == ["frames", "offsets"]
    assert "all, prior 1 mm" in names and "all + compliance, prior 3 mm" in names and names[-1] == "all + compliance"
    assert not any("compliance" in n for n in (c.name for c in parse_params("auto", r)))


def test_prior_weight_is_the_lever_over_the_prior():
    """A prior of s mm holds a parameter whose unit moves the points L mm with weight L / s."""
    r = preset("panda")
    (c,) = parse_params("all", r, ridge_mm=2.0)
    assert c.prior_weight(1.0) == pytest.approx(0.5) and c.prior_weight(600.0) == pytest.approx(300.0)
    (free,) = parse_params("all", r)
    assert free.prior_weight(600.0) == 0.0
