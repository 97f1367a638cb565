"""Paper 000's Figs. 2, 3, 4, 5, 9, 12, 15 and 18 (couplekit issue 16), and Fig. 6 to its end: each test runs the
figure's small variant from ``examples/`` (shortened where the whole run is too long for CI) and checks the
behaviour the figure is about with a number. The bounds are set below what the runs measured (numbers in each docstring,
measured with the 2 CPU cores shared); what the small variants do not show is an xfail, strict, so that it
fails the day it works. docs/examples.md describes each figure, our variant and what differs.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from couplekit.scene import Scene
from couplekit.simulation import Simulation

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def _sim(name: str) -> Simulation:
    return Simulation(Scene.load(EXAMPLES / f"{name}_small.toml"), backend="cpu", log=None)


def _frames(sim: Simulation, n: int) -> None:
    sim.step(n * sim.scene.time.steps_per_frame)


def _grid(sim: Simulation):
    """Cell-centre coordinates (xc, yc, zc) of the scene's grid, m."""
    dom = sim.scene.domain
    return tuple((np.arange(n) + 0.5) * dom.dx for n in dom.resolution)


def _water(sim: Simulation) -> np.ndarray:
    """Water per cell (nz, ny, nx): φ times the fluid fraction, 0 in obstacles."""
    f = sim.fields()
    eps = f.get("sand_fraction", np.zeros_like(f["phi"]))
    return np.where(f["solid"], 0.0, f["phi"] * (1.0 - eps))


def test_fig02_island_floats_under_the_wind():
    """Fig. 2: a 600 kg/m³ sand ring, placed 4 mm above a pool, under a 2 m/s downward air jet. After 0.2 s it
    has dropped onto the water and floats: its lowest particle is below the undisturbed surface (0.06 m) and
    its mean height above 0.045 m (measured 0.044 and 0.0548 m at 0.2 s; 0.0414 and 0.0522 m at 0.27 s,
    settling). Its particles stay within the ring (mean radius 0.1086 m, unchanged to 0.1 mm)."""
    sim = _sim("fig02_wind_island")
    r0 = np.hypot(*(sim.particles()["x"][:2] - 0.3)).mean()
    _frames(sim, 6)
    x = sim.particles()["x"]
    assert x[2].min() < 0.06 and x[2].mean() > 0.045
    assert abs(np.hypot(*(x[:2] - 0.3)).mean() - r0) < 0.005


@pytest.mark.xfail(
    strict=True,
    reason="the wind does not break the island: air at 2 m/s (the lattice Mach limit at the Table 1 dx/dt) "
    "carries ~2.5 Pa of dynamic pressure against ~120 Pa of sand weight per area, and a wind that could (8 m/s) "
    "needs a dt at which Eq. 39's slip term lifts the floating ring by itself (test below; docs/examples.md, Fig. 2)",
)
def test_fig02_wind_breaks_the_island_apart():
    """Fig. 2's point: the airflow breaks the island into fragments that drift apart. Asked of the small
    variant's 0.5 s: the particles' radial spread grows by a quarter (measured: unchanged to 0.1 mm). At 2.4× the
    resolution (session 18, dx = 5 mm, the ring 6 cells thick with its top in clean air) the spread is the same
    with and without the wind (1.012×), and in a patch at the Table 1 dx and dt themselves (session 26) too: the
    wind's shear on the sand is ~0.02 Pa (docs/examples.md, Fig. 2)."""
    sim = _sim("fig02_wind_island")
    s0 = np.hypot(*(sim.particles()["x"][:2] - 0.3)).std()
    _frames(sim, 15)
    assert np.hypot(*(sim.particles()["x"][:2] - 0.3)).std() > 1.25 * s0


@pytest.mark.xfail(
    strict=True,
    reason="Eq. 39's slip term pumps water up through a floating ring at a small dt and lifts it "
    "(docs/fluid-stability.md, 'The slip term at a small time step')",
)
def test_fig02_ring_floats_without_wind_at_a_small_time_step():
    """What blocks Fig. 2's break-up (session 26): a wind strong enough to break the ring (8 m/s, ρ_a U² = 80 Pa
    against the ring's weight per area) needs Δt ≤ ~1e-4 s at this dx to keep the lattice Mach number in bounds,
    and at such a Δt the ring, released 4 mm above the pool with **no wind** (ceiling closed, no inflow), rises
    out of the water by itself. Asked: its mean height never exceeds the release height (0.078 m) over 0.133 s
    (4 frames). Measured at Δt = 6e-5 s: 0.076, 0.076, 0.085, 0.096 m at frames 1-4 (0.114 m at frame 6, then
    it falls back and bobs); at 9e-5 s it rises to 0.087 m, at 1.2e-4 s to 0.075 m from 0.072 m; at 2.32e-4 s
    and at the file's 6.96e-4 s it sinks steadily (0.062 m and 0.055 m at 0.2 s). The pressure in the ring's cells grows
    linearly to 7 kPa by 0.07 s (hydrostatic ~600 Pa) and the water in them rises at 0.2 m/s while the sand
    still falls; without the slip term (u − v)·∇ε of Eq. 39 (a kernel edit in a scratch worktree) the pressure
    stays hydrostatic and the ring sinks, without its water-fraction weight it rises sooner (15 kPa)."""
    sc = Scene.load(EXAMPLES / "fig02_wind_island_small.toml")
    d = sc.to_dict()
    d["time"]["dt"] = 6e-5
    d["domain"]["boundary"]["z_max"] = "wall"
    d["inflows"] = []
    sim = Simulation(Scene.from_dict(d), backend="cpu", log=None)
    z0 = sim.particles()["x"][2].mean()
    heights = []
    for _ in range(4):
        _frames(sim, 1)
        heights.append(sim.particles()["x"][2].mean())
    assert max(heights) <= z0 + 1e-3, f"mean heights {np.round(heights, 4)} from {z0:.4f}"


def test_fig06_raindrop_runs_to_its_last_frame_and_wets_the_bed():
    """Fig. 6's small variant to its end (10 frames, 220 steps): a 2 mm drop at 1.5 m/s lands on the dry bed at
    ~4 ms and its water enters the bed's top. Asked: finite to the end, and at least a fifth of the water below
    4.8 mm (the bed's top is at 4.2 mm; measured 0.353). A guard for changes to Eq. 39's porosity terms: session
    27's effective-porosity form passed every other test but diverged here at step 147, in the air inside the
    dry bed ahead of the drop (docs/fluid-stability.md, 'The slip term at a small time step')."""
    sim = _sim("fig06_raindrop")
    _frames(sim, 10)
    assert np.isfinite(sim.particles()["x"]).all()
    w = _water(sim)
    assert np.isfinite(w).all()
    assert w[_grid(sim)[2] < 0.0048].sum() > 0.2 * w.sum()


def test_fig03_castle_loses_sand_downstream():
    """Fig. 3: the dam (0.25 m long, 0.3 m high) reaches the damp castle at 0.3 s. By 0.43 s sand has been
    carried past the castle's rear face (x > 0.65 m: measured 14 % of the particles) and the castle's top is
    lower (measured 0.1816 m from 0.1887 m)."""
    sim = _sim("fig03_dam_break_castle")
    top0 = sim.particles()["x"][2].max()
    _frames(sim, 13)
    x = sim.particles()["x"]
    assert np.mean(x[0] > 0.65) > 0.05
    assert x[2].max() < top0 - 0.004


def test_fig04_colander_passes_sand_and_water():
    """Fig. 4: a water jet carrying sand (fraction 0.2) falls into the perforated bowl; the whole small variant
    (20 frames, 0.67 s). Sand and water pass its holes: particles below the bowl's bottom (z < 0.13 m; measured
    1132 at 0.37 s, 3820 at 0.67 s) and more water below it than the pool held (measured +3.0 % at 0.37 s,
    +17.4 % at 0.67 s). The run stays stable to its end (it diverged at step ~1036 before the pressure filter's
    three-point wall rule, docs/fluid-stability.md): max lattice speed measured 0.100, volume drift +2.4e-4.
    Measured with the jet's sand retaining water (sand.retention = true, R_a = 0.003; session 22: until then the
    emitted sand of a jet-only scene silently did not retain; then 1008 / 3523 particles, +3 / +18 %)."""
    sim = _sim("fig04_colander")
    zc = _grid(sim)[2]
    below0 = _water(sim)[zc < 0.13].sum()
    speed = 0.0
    for _ in range(sim.scene.time.frames):
        _frames(sim, 1)
        speed = max(speed, sim.diagnostics()["max_lattice_speed"])
    x = sim.particles()["x"]
    assert np.sum(x[2] < 0.13) >= 2500
    assert _water(sim)[zc < 0.13].sum() > 1.10 * below0
    assert np.isfinite(speed) and speed < 0.12, f"max lattice speed {speed}"
    assert abs(sim.diagnostics()["fluid_volume_drift"]) < 1e-3


def _fig05_state(sim: Simulation) -> dict[str, float]:
    """The bailey's state: ``water_out``, the fraction of the water outside the bailey's outer radius (0.45 m,
    at r > 0.48 m); ``crest``, the 99th percentile of the sand height; and, on the side facing the pour (the
    wall within 45° of the direction from the bailey's axis to the pour, x_min) and on the far half (more than
    90° from it), ``near_out`` / ``far_out``, the fraction of that side's sand carried beyond r = 0.5 m (the
    wall's foot is at 0.45 m), and ``near_crest`` / ``far_crest``, the 95th percentile of its sand height."""
    xc, yc, zc = _grid(sim)
    w = _water(sim)
    outside = (np.hypot(*np.meshgrid(xc - 0.75, yc - 0.75, indexing="xy")) > 0.48)[None] & (zc > 0.06)[:, None, None]
    x = sim.particles()["x"]
    pour = sim.scene.inflows[0].center
    r = np.hypot(x[0] - 0.75, x[1] - 0.75)
    towards = np.arctan2(pour[1] - 0.75, pour[0] - 0.75)
    off = np.abs(np.angle(np.exp(1j * (np.arctan2(x[1] - 0.75, x[0] - 0.75) - towards))))  # 0 .. pi
    near, far = off < np.pi / 4, off > np.pi / 2
    return {
        "water_out": float(w[outside].sum() / w.sum()),
        "crest": float(np.percentile(x[2], 99)),
        "near_out": float(np.mean(r[near] > 0.5)),
        "far_out": float(np.mean(r[far] > 0.5)),
        "near_crest": float(np.percentile(x[2][near], 95)),
        "far_crest": float(np.percentile(x[2][far], 95)),
    }


def _assert_breach_after_40_frames(sim: Simulation) -> None:
    """Fig. 5's breach after 40 frames (1.33 s): water outside, the crest lower, the side facing the pour gone
    past the wall's foot while the far half stands, the near crest below the far one."""
    s0 = _fig05_state(sim)
    _frames(sim, 40)
    s = _fig05_state(sim)
    assert s["water_out"] > 0.25
    assert s["crest"] < s0["crest"] - 0.02
    assert s["near_out"] > 0.2
    assert s["far_out"] < 0.02
    assert s["near_crest"] < s["far_crest"] - 0.02


def test_fig05_bailey_breaches_where_the_water_strikes():
    """Fig. 5: water held in a damp sand ring wall, more poured in off the axis (towards x_min). Water seeps out
    through the wetted wall, and by 1.33 s the wall facing the pour has given way: a third of its sand lies
    beyond the wall's foot while the far half stands where it was (measured at 1.33 s: near side 32 % beyond
    r = 0.5 m, far half 0.0 %; 40 % of the water outside; crest 0.250 -> 0.202 m, the near side's 0.159 m against the far half's 0.198 m. At dx = 0.025 m
    instead of 0.03: 32 % and 0.0 %, docs/examples.md)."""
    sim = _sim("fig05_bailey_breach")
    _assert_breach_after_40_frames(sim)


@pytest.mark.slow
def test_fig05_bailey_breaches_where_the_water_strikes_on_a_finer_grid():
    """The CI test's breach at dx = 0.025 m instead of 0.03 m (Δt scaled with dx, the domain 0.5 m tall so that
    it holds whole cells): the same bounds hold (measured at 1.33 s: near side 32 % beyond r = 0.5 m, far half
    0.0 %, the near side's crest 0.16 m against the far half's 0.20 m; 31 % of the water outside)."""
    from couplekit.simulation import with_settings

    scene = with_settings(
        Scene.load(EXAMPLES / "fig05_bailey_breach_small.toml"),
        {"domain.dx": 0.025, "domain.size": [1.5, 1.5, 0.5], "time.dt": 0.00056},
        EXAMPLES,
    )
    sim = Simulation(scene, backend="cpu", log=None)
    _assert_breach_after_40_frames(sim)


@pytest.mark.slow
def test_fig05_bailey_collapses_over_the_whole_run():
    """The whole small variant (3 s): the breach facing the pour has opened down to a third of the wall's height
    and most of the water is outside (measured: near-side crest 0.135 m from 0.25 m, the floor slab's top at
    0.06 m; 64 % of the water outside, 53 % of the near side's sand beyond r = 0.5 m; at dx = 0.025 m 0.12 m, 64 %
    and 58 %)."""
    sim = _sim("fig05_bailey_breach")
    _frames(sim, sim.scene.time.frames)
    s = _fig05_state(sim)
    assert s["near_crest"] < 0.15
    assert s["water_out"] > 0.5
    assert s["near_out"] > 0.4


def test_fig12_bunny_deflects_the_flow():
    """Fig. 12: a dam of water over a sand layer (fraction 0.35) released towards a rigid bunny. At 1.34 s the
    water has gone around it: beside the bunny it stands 0.47 m deep, in its lee 0.03 m (measured); the sand,
    slower, has reached the bunny's front (measured 0.052 m³ of sand upstream of it, none in its lee)."""
    sim = _sim("fig12_bunny_dam_break")
    _frames(sim, 40)
    xc, yc, _ = _grid(sim)
    h = _water(sim).sum(axis=0) * sim.scene.domain.dx  # (ny, nx) water depth
    band, sides = np.abs(yc - 2.0) < 0.5, (np.abs(yc - 2.0) > 0.8) & (np.abs(yc - 2.0) < 1.6)
    lee, beside, upstream = (xc > 6.05) & (xc < 6.7), (xc > 4.6) & (xc < 5.8), (xc > 3.7) & (xc < 4.25)
    h_side, h_lee = h[sides][:, beside].mean(), h[band][:, lee].mean()
    assert h_side > 0.3 and h_side > 5 * h_lee
    eps = sim.fields()["sand_fraction"][:, band]
    assert eps[:, :, upstream].sum() * sim.scene.domain.dx**3 > 0.01
    assert eps[:, :, lee].sum() < 0.1 * eps[:, :, upstream].sum()


def test_fig18_city_floods_and_sand_settles():
    """Fig. 18: a 60 m deep block of seawater released towards a city of 16 towers on a sand layer. By 10 s the
    water covers part of the city's ground (measured 28 % of the open ground columns deeper than 5 m), a
    fifth of the sand has been carried more than a cell (10 m; measured 22 %), and the sand has slowed from its
    peak (mean particle speed measured 4.0 m/s at 4.5 s; 2.0, 1.6, 0.41 m/s over the last three frames: the
    sand still shifts as the water sloshes, so the mean of three frames is compared)."""
    sim = _sim("fig18_city_flood")
    x0 = sim.particles()["x"].copy()
    xc, _, _ = _grid(sim)
    speeds = []
    for _ in range(20):
        _frames(sim, 1)
        speeds.append(float(np.linalg.norm(sim.particles()["v"], axis=0).mean()))
    p = sim.particles()
    h = _water(sim).sum(axis=0) * sim.scene.domain.dx
    city = (xc > 200) & (xc < 490)
    ground = ~sim.fields()["solid"][3][:, city]  # open columns at z = 35 m, above the bedrock
    assert np.mean(h[:, city][ground] > 5.0) > 0.15
    assert np.mean(np.linalg.norm(p["x"] - x0, axis=0) > 10.0) > 0.1
    assert max(speeds) > 2.0 and np.mean(speeds[-3:]) < 0.5 * max(speeds)


def _fig09_foot(sim: Simulation) -> tuple[int, float, float]:
    """Particles past the slope's foot (x > 1.8 m): their count, the spread of their y (m) and mean speed."""
    p = sim.particles()
    foot = p["x"][0] > 1.8
    if not foot.any():
        return 0, 0.0, 0.0
    return int(foot.sum()), float(p["x"][1][foot].std()), float(np.linalg.norm(p["v"][:, foot], axis=0).mean())


def test_fig09_mixture_runs_down_the_slope():
    """Fig. 9, shortened to 0.84 s: the jet carrying sand (fraction 0.3, 1.5 m/s) runs down the 31° slope: the
    sand front has passed x = 1.5 m (measured 1.78 m; the foot is at 1.67 m) and water with it (columns holding
    over 1e-3 m³ of water up to x = 1.125 m, measured). Which front leads is not asserted: here the leading
    sand particles run ahead of the water's bulk, where the paper's water leads (docs/examples.md)."""
    sim = _sim("fig09_slope_delta")
    _frames(sim, 25)
    xc = _grid(sim)[0]
    water_x = _water(sim).sum(axis=(0, 1)) * sim.scene.domain.dx**3
    assert xc[water_x > 1e-3].max() > 0.9
    assert sim.particles()["x"][0].max() > 1.5


@pytest.mark.slow
def test_fig09_delta_forms_at_the_slope_foot():
    """The whole small variant (2 s): sand deposits past the foot and spreads sideways into a fan (measured at
    1.9 s: 1714 particles past x = 1.8 m, their y spread 0.40 m against the outlet's 0.16 m, moving at
    0.43 m/s against the jet's 1.5 m/s; the water front then at 3.2 m, ahead of the sand's 2.7 m)."""
    sim = _sim("fig09_slope_delta")
    _frames(sim, sim.scene.time.frames)
    n, spread, speed = _fig09_foot(sim)
    assert n > 100
    assert spread > 2.0 * 0.54 / np.sqrt(12.0)
    assert speed < 1.0


def _fig15_state(sim: Simulation) -> dict[str, float]:
    """The collapse's ``front`` (99.9th percentile of the particles' x) and, ahead of it (x > front + 2 cm), the
    highest water column ``wave`` (Σ water × dx, mean over y) and where it stands, ``crest`` (m)."""
    xc = _grid(sim)[0]
    h = _water(sim).sum(axis=0).mean(axis=0) * sim.scene.domain.dx
    front = float(np.percentile(sim.particles()["x"][0], 99.9))
    k = int(np.argmax(np.where(xc > front + 0.02, h, 0.0)))
    return {"front": front, "wave": float(h[k]), "crest": float(xc[k])}


def test_fig15_collapse_pushes_a_wave_into_the_layer():
    """Fig. 15, shortened to 0.4 s: the 0.65 m column (L0 = 0.18 m) collapses into the 5 cm layer (h0, five cells)
    and pushes the water up ahead of its front (measured at 0.4 s: front at 0.455 m, the water ahead of it
    0.0705 m high, 1.41 h0; the front ran at 0.93 m/s between 0.23 and 0.4 s, Fr_f = v_f / sqrt(g h0) = 1.33)."""
    sim = _sim("fig15_granular_collapse")
    _frames(sim, 12)
    s = _fig15_state(sim)
    assert s["front"] > 0.4
    assert s["wave"] > 1.25 * 0.05


@pytest.mark.slow
def test_fig15_wave_leaves_the_sand_at_the_solitary_wave_speed():
    """The whole small variant (0.87 s): the wave the collapse raised (its peak 0.0914 m, A/h0 = 0.83, at 0.53 s)
    outruns the sand, which stops at 0.60 m, and travels at the speed of a solitary wave of its height,
    c = sqrt(g (h0 + A)) (Boussinesq; the crest moves 0.90 m/s over the last 0.2 s, against 0.908 m/s for its mean
    height 0.0840 m; tolerance 10 %: the crest is read on the 1 cm grid every frame, ±0.5 cm in 0.2 s)."""
    sim = _sim("fig15_granular_collapse")
    rows = []
    for _ in range(sim.scene.time.frames):
        _frames(sim, 1)
        rows.append(_fig15_state(sim))
    end = rows[-1]
    assert end["crest"] > end["front"] + 0.2
    assert max(r["wave"] for r in rows) > 1.5 * 0.05
    last = rows[-7:]  # the last 0.2 s
    t = np.arange(len(last)) * sim.scene.time.steps_per_frame * sim.scene.time.dt
    speed = np.polyfit(t, [r["crest"] for r in last], 1)[0]
    height = np.mean([r["wave"] for r in last])
    assert speed == pytest.approx(np.sqrt(9.81 * height), rel=0.1)


def _fig17_run(name: str, frames: int) -> tuple[np.ndarray, np.ndarray, Simulation]:
    """sand_top (m) and fluid_volume_drift (0 for a sand-only scene) at frames 0 .. ``frames``."""
    sim = _sim(name)
    rows = []
    for i in range(frames + 1):
        if i:
            _frames(sim, 1)
        d = sim.diagnostics()
        rows.append((d["sand_top"], d.get("fluid_volume_drift", 0.0)))
    tops, drifts = np.array(rows).T
    return tops, drifts, sim


@pytest.fixture(scope="module")
def fig17_wet():
    """The wet Fig. 17 variant to 0.67 s (20 frames, ~50 s on one shared core), shared by two tests."""
    return _fig17_run("fig17_wet_column", 20)


def test_fig17_wet_block_stands_while_dry_block_collapses(fig17_wet):
    """Fig. 17: both blocks stand in the paper's invisible container until 0.3 s (bodies.container_until).
    The wet one, with water poured on it, keeps >= 80 % of its height at every frame to 0.67 s (0.37 s after
    the container went; measured min 95 %: 0.1892 -> 0.1797 m), its top stays wet (saturation above the
    cohesion onset S1 = 0.05 in most of its upper core: measured 0.11 mean); the dry one falls below 60 % by
    0.6 s (measured 0.178 -> 0.084 m, 47 %)."""
    wet, _, sim = fig17_wet
    assert wet.min() >= 0.8 * wet[0], wet / wet[0]
    p = sim.particles()
    x, s = p["x"], p["saturation"]
    core = (np.abs(x[0] - 0.2) < 0.04) & (np.abs(x[1] - 0.2) < 0.04) & (x[2] > 0.1)
    assert np.mean(s[core] > 0.05) > 0.5
    dry, _, _ = _fig17_run("fig17_dry_column", 30)
    assert dry[15] > 0.9 * dry[0]  # 0.3 s: still in its container
    assert dry[-1] < 0.6 * dry[0], dry / dry[0]


def test_fig17_wet_block_keeps_its_water_volume(fig17_wet):
    """Fig. 17's water volume (Σ ε̃ φ + bound water) within 1 % of its start at every frame.  It drifted to
    +0.9 %, +2.5 %, +3.9 %, +4.9 % at 0.34, 0.40, 0.50, 0.67 s as the dry rim fell away, with the volume
    controller at its bound; with the controller's residual put back at the interface
    (FluidSolver._interface_correction) it stays within 0.11 % (measured 553.91–555.01 cells about 554.4)."""
    _, drift, _ = fig17_wet
    assert np.abs(drift).max() < 0.01, drift
