"""A coupled scene whose sand has one density reads the node sand volume as the node mass over that density
(SandSolver.node_volume) instead of a volume grid: the same run to float32 round-off as with the grid kept, for
the schedulers that read the volume at different times (lockstep, sub-cycling, multi-rate), with retention."""

from __future__ import annotations

import numpy as np
import pytest
from sim_scenes import tiny_coupled_moving

from couplekit.scene import Scene
from couplekit.simulation import Simulation

SCHEDULERS = {
    "lockstep": {"kind": "lockstep"},
    "subcycle": {"kind": "subcycle", "substeps": 2},
    "multirate": {"kind": "multirate", "sand_every": 2},
}


@pytest.mark.parametrize("retention", [False, True], ids=["dry", "retention"])
@pytest.mark.parametrize("kind", list(SCHEDULERS))
def test_mass_over_density_runs_as_the_volume_grid(kind, retention):
    scene = Scene.from_dict(tiny_coupled_moving(SCHEDULERS[kind], retention=retention))
    runs = []
    for keep in (False, True):
        sim = Simulation(scene, backend="cpu", log=None, check_memory=False)
        assert sim.sand.grid_vol is None
        if keep:
            sim.sand._keep_volume_grid()  # what a second density would make it do
            assert sim.sand.grid_vol is not None
        sim.step(24)
        runs.append((sim.sand.particles(), sim.fields(), sim.coupler.fields()))
    (pa, fa, ca), (pb, fb, cb) = runs
    assert np.abs(pa["v"]).max() > 0.05  # the sand moves through the water
    scale = np.abs(pa["x"]).max()
    assert np.abs(pa["x"] - pb["x"]).max() <= 1e-5 * scale
    for k in ("phi", "velocity"):
        assert np.abs(fa[k] - fb[k]).max() <= 1e-4 * max(np.abs(fa[k]).max(), 1e-3), k
    for k in ("sand_fraction", "fluid_fraction"):
        assert np.abs(ca[k] - cb[k]).max() <= 1e-4, k
    if retention:
        assert np.abs(ca["bound_water"] - cb["bound_water"]).max() <= 1e-5
