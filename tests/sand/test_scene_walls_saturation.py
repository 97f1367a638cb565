"""Physics of two scene keys, run through the scene path (Scene.from_dict → assemble → the sand solver):

* ``[sand.walls]``: a block sliding on a floor of Coulomb friction μ decelerates at μ g (closed form
  v(t) = v0 − μ g t); on a 'slip' floor, or one of friction 0, it keeps its speed;
* ``bodies[].saturation``: sand that starts damp is cohesive without any water. A dry column collapses, one
  of saturation S = 0.1 stands. S = 0.1 lies on the plateau [S1, S2] = [0.05, 0.18] of the default
  saturation-to-cohesion trapezoid (``sand.cohesion_saturation``; paper 000 Eq. 28 takes "the piecewise linear
  function used in Su et al. 2023", whose breakpoints are not published, couplekit/sand/params.py), where
  c_C = ``sand.cohesion`` = 1000 Pa, far above the ~150 Pa a 16 cm cut needs (Rankine, 4 c / γ × tan(45° +
  φ/2) ≥ h with γ = ε0 ϱ g).
"""

from __future__ import annotations

import numpy as np
import pytest

from couplekit.assembly import assemble
from couplekit.scene import Scene

G = 9.81


def _sliding_block(cpu, floor: dict, v0: float = 1.0, t_end: float = 0.2):
    """A 6 x 4 x 3 cell block (dx = 1 cm) sliding along x at v0 on the floor ``floor`` (a [sand.walls] entry):
    (time, mass-weighted mean v_x) every 10 steps. The block is cohesive (saturation 0.1) so that it slides as
    one piece: a dry block also spreads, shearing its own grains, and decelerates faster than μ g (4.2 m/s²
    at μ = 0.3, measured)."""
    dx, dt = 0.01, 4e-4
    o = 2 * dx  # the MPM walls take 2 node layers
    scene = Scene.from_dict(
        {
            "domain": {"size": [40 * dx, 10 * dx, 10 * dx], "dx": dx},
            "time": {"dt": dt, "frame_duration": dt, "frames": 1},
            "sand": {"density": 1600.0, "youngs_modulus": 1e5, "walls": {"z_min": floor}},
            "bodies": [
                {
                    "kind": "sand",
                    "velocity": [v0, 0.0, 0.0],
                    "saturation": 0.1,
                    "geometry": {"type": "box", "min": [o + dx, 3 * dx, o], "max": [o + 7 * dx, 7 * dx, o + 3 * dx]},
                }
            ],
            "outputs": {"preview": False},
        }
    )
    sand = assemble(scene, cpu, timing=False).sand
    ts, vs = [], []
    for _ in range(int(round(t_end / dt / 10))):
        sand.step(10)
        p = sand.particles()
        ts.append(sand.time)
        vs.append(float((p["mass"] * p["v"][0]).sum() / p["mass"].sum()))
    return np.array(ts), np.array(vs)


@pytest.mark.parametrize("mu", [0.1, 0.3])
def test_block_on_a_friction_floor_decelerates_at_mu_g(cpu, mu):
    """Deceleration within 3 % of μ g (measured 0.3 %: 2.950 vs 2.943 and 0.980 vs 0.981 m/s²), fitted over
    t = 0.03 … 0.18 s (after the block has settled on the floor, before it stops at μ = 0.3)."""
    t, v = _sliding_block(cpu, {"friction": mu})
    sel = (t > 0.03) & (t < 0.18)
    decel = -np.polyfit(t[sel], v[sel], 1)[0]
    assert decel == pytest.approx(mu * G, rel=0.03)
    np.testing.assert_allclose(v[sel], 1.0 - mu * G * t[sel], atol=0.02)  # v0 − μ g t


@pytest.mark.parametrize("floor", [{"kind": "slip"}, {"friction": 0.0}])
def test_block_on_a_frictionless_floor_keeps_its_speed(cpu, floor):
    t, v = _sliding_block(cpu, floor)
    np.testing.assert_allclose(v, 1.0, atol=2e-3)


def _column(cpu, cells: int, saturation: float, cohesion: bool = True, t_end: float = 0.3):
    """Quarter of an 8 x 8 x 16 cm sand column (slip symmetry planes at x_min, y_min: a [sand.walls] use),
    ``cells`` cells across the quarter's 4 cm, released at rest; after ``t_end`` (the dry collapse is over by
    ~0.25 s) the 99.5th percentile height over the initial height, and the same for the spread along x."""
    w, h = 0.04, 0.16
    dx = w / cells
    n_xy, n_z = 5 * cells + 2, int(round(h / dx)) + 5
    o = 2 * dx
    dt = 0.35 * dx / 9.2  # c_p = 9.2 m/s at E = 1e5 Pa, ϱ = 1600 kg/m³
    scene = Scene.from_dict(
        {
            "domain": {"size": [n_xy * dx, n_xy * dx, n_z * dx], "dx": dx},
            "time": {"dt": dt, "frame_duration": dt, "frames": 1},
            "sand": {
                "density": 1600.0,
                "youngs_modulus": 1e5,
                "walls": {"x_min": {"kind": "slip"}, "y_min": {"kind": "slip"}},
            },
            "bodies": [
                {
                    "kind": "sand",
                    "saturation": saturation,
                    "geometry": {"type": "box", "min": [o, o, o], "max": [o + w, o + w, o + h]},
                }
            ],
            "effects": {"cohesion": cohesion},
            "outputs": {"preview": False},
        }
    )
    sand = assemble(scene, cpu, timing=False).sand
    sand.step(int(round(t_end / dt)))
    p = sand.particles()
    assert np.all(p["saturation"] == np.float32(saturation))  # a sand-only scene keeps the seeded value
    x = p["x"]
    return (np.percentile(x[2], 99.5) - o) / h, (np.percentile(x[0], 99.5) - o) / w


@pytest.mark.parametrize("cells", [4, 6])
def test_damp_column_stands_dry_column_collapses(cpu, cells):
    """At 4 and 6 cells across the quarter (789 / 1183 steps): dry, the column falls to 24-26 % of its height
    and spreads 2.6-2.7 times (measured); at S = 0.1 it keeps 93-94 % (elastic settling and the rounded top
    rim) and does not spread."""
    dry_h, dry_w = _column(cpu, cells, 0.0)
    wet_h, wet_w = _column(cpu, cells, 0.1)
    assert dry_h < 0.5 and dry_w > 1.8
    assert wet_h >= 0.8 and wet_w < 1.15


def test_damp_column_collapses_without_cohesion(cpu):
    """The saturation acts through the cohesion only: with effects.cohesion = false the damp column falls as
    the dry one does."""
    h, _ = _column(cpu, 4, 0.1, cohesion=False)
    assert h < 0.5
