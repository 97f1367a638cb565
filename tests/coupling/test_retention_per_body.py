"""Per-body water retention (issue 6, paper Fig. 10: one sand-filled pipe with retention, one without).

Reading of Eqs. 53–56: the retention capacity r_max ε counts only retentive sand, so the coupler rasterises
the retentive sand's fraction ε_r (Eq. 53's P2G with r_p = 1 on retentive particles) and uses
r_max min(ε, ε_r); Eq. 58 hands dR to the retentive particles only (divided by ε_r, so Σ r_p V_p still grows
by V_cell Σ dR).  Scenes set it with ``bodies[*].retention`` (couplekit.simulation passes per-particle flags).
"""

from __future__ import annotations

import numpy as np

from couplekit.scene.model import Scene
from couplekit.simulation import Simulation

DX = 0.005


def _scene(left: bool | None, right: bool | None, sand_retention: bool = True) -> dict:
    """A closed 16 × 8 × 12 box, water up to 8 cells, two 4 × 4 × 4-cell sand blocks resting in it, 8 cells
    apart (their B-spline stencils never share a node)."""
    blocks = []
    for x0, ret in ((2, left), (10, right)):
        body = {"kind": "sand", "geometry": {"type": "box", "min": [x0 * DX, 2 * DX, 2 * DX], "max": [(x0 + 4) * DX,
                6 * DX, 6 * DX]}}  # fmt: skip
        if ret is not None:
            body["retention"] = ret
        blocks.append(body)
    return {
        "scene": {"name": "two_blocks"},
        "domain": {"size": [16 * DX, 8 * DX, 12 * DX], "dx": DX},
        "time": {"dt": 1e-4, "frame_duration": 1e-3, "frames": 1},
        "fluid": {"water_lattice_viscosity": 1e-3, "surface_tension": 0.0},
        "sand": {"density": 1500.0, "youngs_modulus": 1e5, "retention": sand_retention, "absorption_rate": 0.01},
        "bodies": [
            {"kind": "water", "geometry": {"type": "box", "min": [0, 0, 0], "max": [16 * DX, 8 * DX, 8 * DX]}},
            *blocks,
        ],  # fmt: skip
        "outputs": {"preview": False},
    }


def _sim(d: dict) -> Simulation:
    return Simulation(Scene.from_dict(d), backend="cpu", threads=1, log=None)


def _water(sim: Simulation) -> tuple[float, float]:
    """(free Σ ε̃ φ over fluid cells, bound Σ r_p V_p / V_cell)."""
    be = sim.fluid.backend
    e = be.to_host(sim.fluid.fluid_fraction)[1:-1, 1:-1, 1:-1].astype(np.float64)
    phi = be.to_host(sim.fluid.phi)[1:-1, 1:-1, 1:-1].astype(np.float64)
    fluid = be.to_host(sim.fluid.flags)[1:-1, 1:-1, 1:-1] == 0
    r = be.to_host(sim.coupler.moisture_ratio).astype(np.float64)
    vol = be.to_host(sim.sand.volume).astype(np.float64)
    return float((e * phi)[fluid].sum()), float((r * vol).sum() / DX**3)


def test_retention_on_one_body_only():
    """Left block retentive, right not (300 steps): the right block's particles never hold bound water
    (exactly 0) and no node near it binds any; the left block's particles do (> 5 cell volumes, measured
    10.75, the block near capacity); R ≤ r_max min(ε, ε_r) on every node; free + bound water conserved to
    1 % (measured 2.8e-4)."""
    sim = _sim(_scene(True, False, sand_retention=False))
    c = sim.coupler
    assert c.retention and c.retain is not None
    flags = np.asarray(c.fluid.backend.to_host(c.retain)) > 0
    x0 = sim.sand.backend.to_host(sim.sand.x)[0]
    assert flags.any() and not flags.all() and (x0[flags] < 8 * DX).all() and (x0[~flags] > 8 * DX).all()
    sim.step(1)
    w0 = sum(_water(sim))
    sim.step(299)
    assert sim.sand is not None and np.isfinite(sim.fluid.backend.to_host(sim.fluid.f)).all()
    r = sim.fluid.backend.to_host(c.moisture_ratio)
    assert (r[~flags] == 0).all(), "a non-retentive particle gained bound water"
    vol = sim.sand.backend.to_host(sim.sand.volume).astype(np.float64)
    held = float((r[flags] * vol[flags]).sum() / DX**3)
    assert held > 5.0, held
    bound = c.fields()["bound_water"].astype(np.float64)
    right = bound[:, :, 9:]  # the right block's nodes and its stencil (x >= 9 cells)
    assert (right == 0).all(), float(right.max())
    volume, scale = sim.sand.node_volume
    eps = np.minimum(c.params.eps_max, c.fluid.backend.to_host(volume).astype(np.float64) * scale / DX**3)
    cap = c.params.r_max * np.minimum(eps, c.fluid.backend.to_host(c.retentive).astype(np.float64))
    assert (bound <= cap * (1 + 1e-5) + 1e-6).all()
    drift = sum(_water(sim)) / w0 - 1
    print(f"bound {held:.3f} cells, drift {drift:.2e}")
    assert abs(drift) < 0.01, drift


def test_every_body_retentive_is_the_one_setting_model_bitwise():
    """bodies[*].retention = true on both blocks (sand.retention = false) runs bitwise like sand.retention =
    true: all flags true selects the unmasked kernels (no retentive-fraction P2G)."""
    a = _sim(_scene(None, None, sand_retention=True))
    b = _sim(_scene(True, True, sand_retention=False))
    assert b.coupler.retain is None
    a.step(40)
    b.step(40)
    for name in ("f", "phi"):
        assert np.array_equal(
            a.fluid.backend.to_host(getattr(a.fluid, name)), b.fluid.backend.to_host(getattr(b.fluid, name))
        )
    assert np.array_equal(
        a.fluid.backend.to_host(a.coupler.moisture_ratio), b.fluid.backend.to_host(b.coupler.moisture_ratio)
    )


def test_per_body_retention_restarts_bitwise(tmp_path):
    """A checkpoint of a scene with retention on one body only restores the per-particle flags: 20 + 20 steps
    through save/load equal 40 steps straight (fluid populations and moisture ratios bitwise)."""
    a = _sim(_scene(True, False, sand_retention=False))
    a.step(20)
    path = a.save(tmp_path / "mixed.h5")
    b = Simulation.load(path, backend="cpu", threads=1, log=None)
    assert b.coupler.retain is not None
    a.step(20)
    b.step(20)
    be = a.fluid.backend
    assert np.array_equal(be.to_host(a.fluid.f), be.to_host(b.fluid.f))
    assert np.array_equal(be.to_host(a.coupler.moisture_ratio), be.to_host(b.coupler.moisture_ratio))
    assert np.array_equal(be.to_host(a.coupler.retain), be.to_host(b.coupler.retain))
