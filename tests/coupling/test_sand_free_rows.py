"""Host kernels of a mixture skip the mixture's stencils in rows with no sand around them
(:attr:`couplekit.fluid.kernel_ops.KernelOps.skip_sand_free_rows`: the pressure update's grad eps and div v):
there the fluid fraction is exactly 1 and the sand velocity exactly 0, so the stencils' terms are exactly 0.
Checked: bitwise the same states as running every row's stencils, in coupled scenes whose sand fills a small
part of the grid (Fig. 13's ball, a moving block in a tiny tank, Fig. 16's sand pile under a dam break) and on a
kernel state where a sand blob meets walls. (The flow collide's one grad eps stencil was tried the same way: no
measurable gain, not kept.)"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parents[1] / "scene"))
sys.path.insert(0, str(Path(__file__).parents[1] / "fluid"))
from fluid_states import BOUNDARY_SETS, random_state  # noqa: E402
from sim_scenes import tiny_coupled  # noqa: E402

from couplekit.fluid import KernelOps  # noqa: E402
from couplekit.fluid.kernel_ops import KernelOps as _KernelOps  # noqa: E402
from couplekit.scene import Scene  # noqa: E402
from couplekit.simulation import Simulation  # noqa: E402

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


def _tiny() -> Scene:
    d = tiny_coupled()
    d["bodies"][-1]["geometry"].update({"min": [0.006, 0.006, 0.006], "max": [0.010, 0.010, 0.012]})
    d["bodies"][-1]["velocity"] = [0.2, 0.0, -0.3]
    return Scene.from_dict(d)


CASES = {
    "tiny": _tiny,
    "fig13": lambda: Scene.load(EXAMPLES / "fig13_sand_drop_beaker_small.toml"),
    "fig16": lambda: Scene.load(EXAMPLES / "fig16_dam_break_sand_small.toml"),
}


@pytest.mark.parametrize("case", list(CASES))
def test_skipping_sand_free_rows_changes_nothing(case, monkeypatch):
    """Every state array after 7 steps, skipping against not skipping: bitwise equal."""
    skip = Simulation(CASES[case](), backend="cpu", log=None)
    skip.step(7)
    monkeypatch.setattr(_KernelOps, "skip_sand_free_rows", False)
    every = Simulation(CASES[case](), backend="cpu", log=None)
    every.step(7)
    eps = np.asarray(every.fluid.fluid_fraction)
    assert 0 < np.mean(eps != 1.0) < 0.5  # sand in part of the grid only: some rows skip, some do not
    a, b = skip._states(), every._states()
    for solver in a:
        for k in a[solver]:
            assert np.asarray(a[solver][k]).tobytes() == np.asarray(b[solver][k]).tobytes(), (solver, k)


@pytest.mark.parametrize("parity", [0, 1])
def test_pressure_update_with_a_sand_blob_is_the_same_skipping_or_not(kernel_backend, parity, monkeypatch):
    """A random mixed-boundary state whose sand (ε < 1, v ≠ 0) is a blob in one corner: p bitwise the same."""
    effects = {"two_phase": True, "surface_tension": True, "mixture": True, "external_force": True}
    s = random_state(91 + parity, BOUNDARY_SETS["mixed"])
    eps, v = s["eps"], s["sand_v"]
    free = np.ones(eps.shape, bool)
    free[:4, :4, :4] = False
    eps[free] = 1.0
    v[:, free] = 0.0
    args = (s["f"], s["flags"], s["velocity"], s["phi"], eps, v, s["slip"])
    p_skip, p_every = s["p"].copy(), s["p"].copy()
    KernelOps(kernel_backend, **effects).macro_pressure(*args, p_skip, parity, 1.0, 0.00125)
    monkeypatch.setattr(_KernelOps, "skip_sand_free_rows", False)
    KernelOps(kernel_backend, **effects).macro_pressure(*args, p_every, parity, 1.0, 0.00125)
    assert p_skip.tobytes() == p_every.tobytes()
    assert np.abs(p_skip - s["p"]).max() > 1e-5


_SHAPE = (9, 10, 27)  # nz, ny, nx: 29-cell padded rows, scanned as three 8-lane blocks and a remainder of 5


@pytest.mark.parametrize("x", [0, 1, 7, 8, 15, 16, 23, 24, 27, 28])
@pytest.mark.parametrize("field", ["eps", "sand_v"])
def test_one_sandy_cell_anywhere_in_a_row_is_seen(kernel_backend, field, x, monkeypatch):
    """The host's sand-free row scan (an 8-lane scan of bit patterns and a scalar remainder,
    kernels/common.cuh ck_any_differs) must see a single cell of sand at any padded x, in a block or in the
    remainder, ghosts included: p bitwise the same skipping or not, and (a porosity cell) different from a state
    with no sand. A sand velocity where ε = 1 changes no term of Eq. 39 ((1 − ε) div v and (u − v)·∇ε), so there
    only the first holds."""
    effects = {"two_phase": True, "surface_tension": True, "mixture": True, "external_force": True}
    s = random_state(7, BOUNDARY_SETS["periodic"], shape=_SHAPE, obstacle=False)
    eps, v = s["eps"], s["sand_v"]
    eps[...] = 1.0
    v[...] = -0.0  # a negative zero is no sand (as the float comparison it replaced said)
    z, y = _SHAPE[0] // 2 + 1, _SHAPE[1] // 2 + 1
    if field == "eps":
        eps[z, y, x] = 0.7
    else:
        v[2, z, y, x] = 0.01
    args = (s["f"], s["flags"], s["velocity"], s["phi"], eps, v, s["slip"])
    p_skip, p_every, p_clean = s["p"].copy(), s["p"].copy(), s["p"].copy()
    KernelOps(kernel_backend, **effects).macro_pressure(*args, p_skip, 0, 1.0, 0.00125)
    monkeypatch.setattr(_KernelOps, "skip_sand_free_rows", False)
    KernelOps(kernel_backend, **effects).macro_pressure(*args, p_every, 0, 1.0, 0.00125)
    assert p_skip.tobytes() == p_every.tobytes()
    if field == "sand_v":
        return
    clean = (s["f"], s["flags"], s["velocity"], s["phi"], np.ones_like(eps), np.zeros_like(v), s["slip"])
    KernelOps(kernel_backend, **effects).macro_pressure(*clean, p_clean, 0, 1.0, 0.00125)
    assert p_every.tobytes() != p_clean.tobytes()
