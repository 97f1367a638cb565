"""CouplingParams validation, the closed forms it documents, and the ops factory."""

from __future__ import annotations

import math

import pytest

from couplekit.backend import get_backend
from couplekit.coupling import CouplingParams, KernelOps, ReferenceOps, drag_area, make_coupling_ops


@pytest.mark.parametrize(
    "kwargs, word",
    [
        ({"drag_coefficient": 0.0}, "drag_coefficient"),
        ({"eps_max": 1.0}, "eps_max"),
        ({"r_max": 0.6}, "r_max"),  # (1 - 0.64)/0.64 = 0.5625: bound water would fill the pores
        ({"absorption_rate": 1.5}, "absorption_rate"),
        ({"grain_diameter": -1e-4}, "grain_diameter"),
    ],
)
def test_invalid_parameters_are_refused_by_name(kwargs, word):
    with pytest.raises(ValueError, match=word):
        CouplingParams(**kwargs)


def test_default_retention_capacity_is_the_wet_threshold():
    """r_max ε_max = (1 − ε_max)/2: sand at capacity is exactly paper 000's "wet" threshold (§5.1)."""
    p = CouplingParams()
    assert abs(p.r_max * p.eps_max - (1 - p.eps_max) / 2) < 3e-3


def test_drag_areas():
    """Ball of volume V: π r² with r = (3V/4π)^(1/3); N grains of diameter d: N π d²/4 = 1.5 V/d."""
    v = 0.3 * 1e-6
    r = (3 * v / (4 * math.pi)) ** (1 / 3)
    assert math.isclose(drag_area(0.3, 1e-6), math.pi * r * r, rel_tol=1e-12)
    d = 2e-4
    n = v / (math.pi * d**3 / 6)
    assert math.isclose(drag_area(0.3, 1e-6, d), n * math.pi * d * d / 4, rel_tol=1e-12)


def test_factory_picks_kernels_or_reference(cpu):
    assert isinstance(make_coupling_ops(cpu), KernelOps)
    assert isinstance(make_coupling_ops(get_backend("numpy")), ReferenceOps)
    with pytest.raises(ValueError, match="kernel backend"):
        KernelOps(get_backend("numpy"))
