"""The lattice tables in kernels/lattice.cuh agree with couplekit/lattice.py, and have the right moments."""

from __future__ import annotations

import re
from fractions import Fraction

import numpy as np
import pytest

from couplekit.backend.sources import kernel_dir
from couplekit.lattice import C7, C27, CS2, CS2_7, OPP7, OPP27, W7, W27


def _header_table(name: str) -> np.ndarray:
    text = (kernel_dir() / "lattice.cuh").read_text()
    m = re.search(rf"CONSTANT \w+ {name}\[\d+\] = \{{([^}}]*)\}};", text)
    assert m, f"{name} not found in lattice.cuh"
    items = [s.strip() for s in m.group(1).split(",")]
    return np.array([float(Fraction(s.replace(".f", "").replace(" ", ""))) for s in items])


@pytest.mark.parametrize("c, w, suffix", [(C27, W27, "27"), (C7, W7, "7")])
def test_header_matches_python(c, w, suffix):
    for axis, name in enumerate("XYZ"):
        np.testing.assert_array_equal(_header_table(f"C{name}{suffix}"), c[:, axis])
    np.testing.assert_allclose(_header_table(f"W{suffix}"), w, rtol=1e-15)


@pytest.mark.parametrize("c, w, cs2", [(C27, W27, CS2), (C7, W7, CS2_7)])
def test_isotropy(c, w, cs2):
    assert w.sum() == pytest.approx(1.0)
    np.testing.assert_allclose(w @ c, 0.0, atol=1e-15)  # first moment
    np.testing.assert_allclose(np.einsum("q,qa,qb->ab", w, c, c), cs2 * np.eye(3), atol=1e-15)  # second


def test_opposites_are_adjacent_pairs():
    for opp in (OPP27, OPP7):
        assert opp[0] == 0
        q = np.arange(1, len(opp))
        np.testing.assert_array_equal(opp[1:], np.where(q % 2 == 1, q + 1, q - 1))
    np.testing.assert_array_equal(C27[OPP27], -C27)
