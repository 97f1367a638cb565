"""Physical validation of the sand solver: granular column collapse (axisymmetric, aspect ratios 0.5 and
2), the angle of repose of a slumped cone, and a cohesive (wet) block that stands while a dry one
collapses (paper 000 Fig. 17).

Column collapse reference: Lube, Huppert, Sparks & Hallworth, "Axisymmetric collapses of granular
columns", J. Fluid Mech. 508 (2004): runout (R_inf - R0)/R0 = 1.24 a for a < 1.7 and 1.6 a^(1/2) above
(prefactors as quoted in ../shared/notes/mpm-method.md Sec. 6.1; the note flags them as recalled, not
re-checked against the PDF); final height H_inf = H0 for a < 0.74 (the top of a squat column does not
move).  Quarter of the column: slip walls on the two symmetry planes, separating floor with Coulomb
friction 0.5, R0 = 8 cm on 8 cells (6 in the CI-sized runs), 2^3 particles per cell.

What the investigation of the runout deficit found (issue 4; numbers from these runs, R0 = 8 cells):

* not the boundaries: the quarter domain with slip symmetry planes gives the full-domain runout (0.337 vs
  0.337 at a = 0.5, paper sand; 0.362 vs 0.365 at 30 deg), separating symmetry planes the same; a sticky
  floor gives what friction 0.5 gives (0.358 vs 0.362 at 30 deg).  Lube et al. report the runout
  independent of the base (wood, baize, Plexiglas, sandpaper), so the floor is the paper's 0.5.
* not the volume correction (0.361 without it), nor Young's modulus (1e6 Pa: 0.321), nor particles per
  cell (3^3: 0.362); resolution moves it a little (R0 = 16 cells: 0.404 at 30 deg).
* a bug in the hardening state (fixed): the apex case counted the stored volume-correction gain as
  plastic flow every step, so q grew at rest (mean q 3 -> 9 in 0.15 s after the column stopped); the
  runout hardly changed (0.337 -> 0.345), since the deposit forms before that mattered.
* the cause is the friction angle.  A rate-independent Drucker-Prager continuum deposits a squat column
  quasi-statically: its flank stands at about the friction angle, and the runout is that of a truncated
  cone with a straight flank at phi (0.40 at 30 deg, 0.49 at 25, 0.61 at 20 deg: measured 0.36, 0.45,
  0.59).  Lube's 1.24 a needs a mean flank of ~21 deg (their deposits end in a thin tail a few grains
  thick, which a 1 cm grid cannot hold).  The paper's sand (Klar hardening 25 -> 48 -> 35 deg) hardens
  while it flows: its particles end at a mean of 31 deg (a = 0.5) and 41 deg (a = 2), which gives
  0.345 and 1.07, -44 % and -53 % of Lube.  One constant angle, 20 deg, puts both branches of Lube's
  scaling within 20 % (-5 % and +16 %; 25 deg: -27 %, -7 %; 30 deg: -42 %, -28 %).  Continuum
  (mu(I)) reproductions of column collapses likewise use a static friction coefficient well below the
  repose angle of sand (mu_s = 0.32, 17.7 deg, in Lagree, Staron & Popinet, J. Fluid Mech. 686, 2011 —
  as recalled, not re-checked).  So the runout validation runs a 20 deg sand, and the paper's sand is
  checked for the deficit it legitimately has.
* since issue 16 the 20 deg sand also has a viscoplastic overstress of 1.5 Pa s (``SandParams.viscosity``):
  without it the runout did not converge with the grid (a = 2: 2.30, 2.61, 2.85, 3.01 at R0 = 6, 8, 12,
  16 cells; a = 0.5 up to 0.659), with it the a = 2 runout is 2.15, 2.34, 2.45, 2.49 and a = 0.5 0.545,
  0.575, 0.604, 0.609 (docs/sand-validation.md).

The creep of settled deposits (issue 4, open; measured on the slumped 45 deg cone of
test_slumped_cone_stands_at_the_friction_angle, 30 deg sand, R = 12 cells: toe radius 12.08, 12.28,
12.51, 12.64 cells and flank 27.2, 26.1, 25.2, 24.5 deg at t = 0.3, 0.5, 1.0, 1.5 s; the rate decays
slowly, roughly like 1/t).  What it is not, each by a run that changes only that:

* not elastic ringing: zeroing every particle velocity and C at t = 0.5 s leaves the drift as it was
  (toe 12.635 vs 12.64 at 1.5 s); damping the grid velocity at 20 /s from t = 0.3 s (ringing would be
  gone in 0.1 s) only slows it (toe 12.23 -> 12.56, flank 27.1 -> 25.9 deg over 0.5-1.5 s); the kinetic
  energy left (rms ~1.5 mm/s) is the creep itself.
* not the state the collapse left: resetting F = I, tau = 0, vc = 0 (and v, C = 0) at t = 0.5 s, so that
  only the particle positions remain, creeps the same (toe 12.63 at 1.5 s).
* not the volume correction (off: toe 12.61), nor the time step (dt = 0.12 dx/c_p instead of 0.35: the
  same drift per unit time, 0.34 vs 0.37 cells over 0.5-1.5 s, so no per-step ratchet), nor particles per
  cell (3^3: 0.35 cells), nor the floor (friction 1e6: identical), nor the round-off of rebuilding
  F = U exp(e) V^T every step (an experimental G2P that keeps F_trial when the return mapping leaves the
  strains unchanged: identical toe).  A stiffer sand (4 E) stands steeper after the slump and then creeps
  more (30.3 -> 25.7 deg over 0.5-1.5 s).
* a fresh cone built BELOW the friction angle creeps too: a 25 deg cone of 30 deg sand at rest from
  t = 0 moves its toe 11.46 -> 11.66 cells over 0.3-1.5 s (its flank does not flatten: 24.6 -> 24.9 deg),
  and even with 45 deg sand by 0.04 cells; the same cone of a purely elastic (no plasticity) Hencky solid
  is still to round-off (toe 11.354 at every time, kinetic energy 7e-13 J/kg).  So the creep needs the
  plasticity and a free surface, and not a steep slope.
* where: in the slumped cone at t = 1 s, 50-70 % of the particles down to 3 cells below the free surface
  sit exactly at the cone's apex (stress-free, |e| < 1e-6) step after step, next to particles carrying
  4-5x the hydrostatic compression (force chains between grid-invisible stress-free particles); the
  hydrostatic strain 2 cells deep would be -1.8e-3, the median there is -5e-7.  The creeping layer is
  the same 3-4 cells (mean speed 4.2, 2.7, 1.4, 0.44, 0.1 mm/s at 0-0.5, 0.5-1, 1-2, 2-3, 3-4 cells).
* it is a free-surface layer effect of the coarse grid, not of the material: at half the grid spacing
  (dx = 5 mm, R = 24 cells, 8x the particles) the slumped cone's flank stops drifting (26.2, 27.1,
  27.5 deg at t = 0.5, 1.0, 1.5 s, against 26.1, 25.2, 24.5 at dx = 1 cm) and the 25 deg cone's toe moves
  0.65 mm over 0.3-1.5 s instead of 2 mm (its kinetic energy is 16x lower); only the thin tail of the
  slumped deposit still spreads (toe +2.0 mm over 1.0-1.5 s, +1.3 mm at 1 cm).  A cohesion of 20 Pa
  (10 % of rho g dx; it moves the apex into tension) halves the creep at dx = 1 cm (25 deg cone toe
  +0.10 instead of +0.20 cells, slumped cone +0.16 instead of +0.37), and dropping the APIC affine term
  from the momentum transfer after t = 0.5 s (PIC: far more dissipative) cuts it about 5x (toe +0.07
  cells, flank 26.1 -> 25.7 deg over 0.5-1.5 s).
So the creep lives in the 1-3 cells under the free surface whose particles the Drucker-Prager apex case
holds at zero stress and zero strength; it shrinks with the grid spacing and decays roughly like 1/t.
No defect in the code was found that causes it, so there is nothing to fix short of a finer grid (or a
numerical cohesion, which the model does not have); the tests read their deposits at stated times.
"""

from __future__ import annotations

import numpy as np
import pytest

from couplekit.sand import DomainWalls, SandParams, SdfCollider, Wall
from couplekit.sand.seeding import seed_box, seed_sdf
from couplekit.sand.solver import SandSolver

BOUND = 2
R0 = 0.08  # column radius, m
LUBE_SAND = SandParams(hardening=False, h0=20.0, viscosity=1.5)
"""Constant 20 deg: the one angle (of 20, 25, 30) that puts both branches of Lube's scaling within 20 %; with
the viscosity 1.5 Pa s that makes the runout converge with the grid (issue 16)."""


def lube_2004(a: float) -> float:
    """Axisymmetric runout (R_inf - R0)/R0 of Lube et al. 2004."""
    return 1.24 * a if a < 1.7 else 1.6 * a**0.5


def _collapse(cpu, a: float, t_end: float, r0_cells: int, params: SandParams):
    dx = R0 / r0_cells
    h0_cells = int(round(a * r0_cells))
    n_r = BOUND + int(r0_cells * (1 + 1.3 * lube_2004(a))) + 4
    nz = BOUND + h0_cells + 4
    h0, o = h0_cells * dx, BOUND * dx

    def column(p):
        return np.maximum(np.hypot(p[:, 0] - o, p[:, 1] - o) - R0, np.maximum(o - p[:, 2], p[:, 2] - (o + h0)))

    body = seed_sdf(column, (o, o, o), (o + R0, o + R0, o + h0), dx, ppc=2, jitter=0.5, seed=1)
    walls = DomainWalls.from_dict(
        {"-x": Wall("slip"), "-y": Wall("slip"), "-z": Wall("separate", 0.5)}, default=Wall("separate")
    )
    dt = 0.35 * dx / params.p_wave_speed
    sol = SandSolver(cpu, (nz, n_r, n_r), dx, dt, params, body.x, body.volume, walls=walls)

    def runout(x):  # 99.5 %: ignore a few isolated particles at the front
        return np.percentile(np.hypot(x[0] - o, x[1] - o), 99.5) / R0 - 1.0

    sol.step(int((t_end - 0.1) / dt))
    earlier = runout(sol.particles()["x"].astype(np.float64))
    sol.step(int(t_end / dt) - sol.steps)
    p = sol.particles()
    x = p["x"].astype(np.float64)
    r = np.hypot(x[0] - o, x[1] - o)
    return {
        "runout": runout(x),
        "front_drift": abs(runout(x) - earlier),  # over the last 0.1 s
        "height": (np.percentile(x[2], 99.5) - o) / R0,
        "free_room": (n_r - BOUND - 1) * dx - r.max(),  # > 0: the far walls never stopped the front
        "friction_angle": float(p["friction_angle"].mean()),
        "kinetic_energy": sol.diagnostics()["kinetic_energy"],
        "mass0": body.volume.sum() * params.density,
        "mass": sol.diagnostics()["mass"],
    }


# The runout is read when the collapse is over (kinetic energy down 3 decades from its peak), not "at
# infinity": the deposit's toe then keeps creeping at ~0.1 R0/s, slowing roughly like 1/t
# (R0 = 6 cells, a = 0.5, 20 deg: 0.555, 0.573, 0.593, 0.609, 0.628 at t = 0.35, 0.5, 0.7, 0.9, 1.2 s;
# paper sand 0.320 -> 0.392; the a = 2 fronts hardly move): the coarse-grid free-surface creep of the
# module docstring (not elastic ringing); front_drift bounds it over the last 0.1 s.
# R0 = 8 cells: ~20 M particle-steps for the four runs (25 s on one idle core, far more on a loaded 2-core
# runner), so slow; R0 = 6 cells (~3x fewer) is the CI-sized version.  The fronts stop by t = 0.25 s
# (a = 0.5) and 0.45 s (a = 2).
RESOLUTIONS = [pytest.param(6, id="r0_6_cells"), pytest.param(8, id="r0_8_cells", marks=pytest.mark.slow)]
# the Lube sand has no hardening state to update and runs faster: R0 = 8 cells (6 s) in CI as well, so that
# the runout is checked at two resolutions; R0 = 12 cells (30 s) is slow
LUBE_RESOLUTIONS = [
    pytest.param(6, id="r0_6_cells"),
    pytest.param(8, id="r0_8_cells"),
    pytest.param(12, id="r0_12_cells", marks=pytest.mark.slow),
]
_RUNS: dict = {}


def _collapses(cpu, r0_cells: int, sand: str) -> dict:
    key = (r0_cells, sand)
    if key not in _RUNS:
        params = LUBE_SAND if sand == "lube" else SandParams()
        _RUNS[key] = {a: _collapse(cpu, a, t, r0_cells, params) for a, t in ((0.5, 0.35), (2.0, 0.5))}
    return _RUNS[key]


@pytest.mark.parametrize("r0_cells", LUBE_RESOLUTIONS)
def test_column_collapse_runout_within_20_percent_of_lube_2004(cpu, r0_cells):
    """Both branches of Lube's scaling (a = 0.5 linear, a = 2 square root) within the issue's 20 % with one
    constant friction angle, 20 deg, and the viscosity 1.5 Pa s (module docstring: why not the paper's
    sand).  Measured: R0 = 6 cells 0.545 / 2.15 (-12 % / -5 %), 8 cells 0.575 / 2.34 (-7 % / +4 %), 12 cells
    0.604 / 2.45 (-3 % / +8 %); without the viscosity 0.555 / 2.30, 0.589 / 2.61, 0.636 / 2.85 (+26 %, and
    16 cells +33 %: it did not converge).  Also H_inf = H0 within a
    cell for the squat column is Lube's a < 0.74 regime... up to the top edge rounding: 20 deg loses
    more of the rim (H/R0 = 0.39 at R0 = 8 cells), so only the tall column's height loss is checked."""
    runs = _collapses(cpu, r0_cells, "lube")
    for a, c in runs.items():
        assert c["free_room"] > 0
        assert c["front_drift"] < 0.04  # collapse over; only the slow creep below is left (0.0002-0.029)
        assert c["kinetic_energy"] < 1e-5 * c["mass"]  # at rest (rms speed < 4.5 mm/s)
        assert c["runout"] == pytest.approx(lube_2004(a), rel=0.20), (a, c["runout"])
    assert runs[2.0]["height"] < 0.6 * 2.0


@pytest.mark.slow
def test_lube_sand_axisymmetric_runout_converges(cpu):
    """R0 = 12 -> 16 cells (80 s on one core, with R0 = 12 run before): the runout moves +0.8 % (a = 0.5: 0.604 -> 0.609) and +1.5 %
    (a = 2: 2.452 -> 2.489), within 3 %; without the viscosity +3.6 % and +5.6 % (0.636 -> 0.659, 2.85 ->
    3.01), the increments from R0 = 6 cells on not shrinking (a = 2: +0.31, +0.24, +0.16 against +0.19,
    +0.11, +0.04 with it)."""
    coarse, fine = _collapses(cpu, 12, "lube"), _collapses(cpu, 16, "lube")
    for a in (0.5, 2.0):
        assert fine[a]["runout"] == pytest.approx(coarse[a]["runout"], rel=0.03), a
        assert fine[a]["runout"] == pytest.approx(lube_2004(a), rel=0.20), a


@pytest.mark.parametrize("r0_cells", RESOLUTIONS)
def test_paper_sand_collapse_settles_and_runs_short_for_its_friction(cpu, r0_cells):
    """The paper's sand (Klar hardening): the columns come to rest with mass conserved, a squat column
    keeps its top (H_inf/R0 = a within one cell, Lube 2004), a tall one loses height, the runout grows
    with a — and falls short of Lube by 40-60 % (measured R0 = 8 cells: 0.345 / 1.07, -44 % / -53 %;
    R0 = 6: 0.320 / 1.06), because the sand hardens while it flows: the particles end at a mean friction
    angle above 30 deg (31 deg at a = 0.5, 40 deg at a = 2) and a Drucker-Prager deposit stands at its
    friction angle (module docstring).  The bounds fail if the deficit disappears or grows, either of
    which would mean the model changed."""
    runs = _collapses(cpu, r0_cells, "paper")
    squat, tall = runs[0.5], runs[2.0]
    for a, c in runs.items():
        assert c["free_room"] > 0
        assert c["front_drift"] < 0.04  # collapse over; only the slow creep below is left (0.024-0.027)
        # at rest up to the surface creep of the deposit (module docstring): rms speed < 1.4 cm/s
        # (measured 2.3e-5 m2/s2, rms 6.8 mm/s, at R0 = 6 cells, a = 0.5; 7e-6 at R0 = 8 cells)
        assert c["kinetic_energy"] < 1e-4 * c["mass"]
        assert c["mass"] == pytest.approx(c["mass0"], rel=1e-6)
        assert 0.40 < 1.0 - c["runout"] / lube_2004(a) < 0.60, (a, c["runout"])
    assert squat["height"] == pytest.approx(0.5, abs=1.0 / r0_cells)
    assert tall["height"] < 0.6 * 2.0
    assert 0.2 < squat["runout"] < tall["runout"]
    assert 30.0 < squat["friction_angle"] < tall["friction_angle"]


def _flank_angle(x: np.ndarray, o: float, dx: float) -> tuple[float, float]:
    """Slope (degrees) of a pile's free surface and its height: the top particle of each dx/2 x dx/2 column
    of the (quarter) pile, least-squares line of height against radius over the columns whose top lies
    between 20 % and 80 % of the pile height (the height: 99th percentile of the tops), so that neither
    the rounded summit nor the toe enters (notes/mpm-method.md Sec. 6.3).  Only the outer flank counts:
    columns at or beyond the median radius of the highest 1 % (a poured heap may keep a crater where the
    jet landed).  Particles that sit a little inside the symmetry planes (x or y < o, within the wall
    layer) belong to the first column."""
    b = dx / 2
    ix = np.maximum(np.floor((x[0] - o) / b), 0).astype(np.int64)
    iy = np.maximum(np.floor((x[1] - o) / b), 0).astype(np.int64)
    key = ix * 1_000_000 + iy
    order = np.argsort(key)
    keys, start = np.unique(key[order], return_index=True)
    top = np.maximum.reduceat(x[2][order] - o, start)
    r = np.hypot((keys // 1_000_000 + 0.5) * b, (keys % 1_000_000 + 0.5) * b)
    height = np.percentile(top, 99)
    r_summit = np.median(r[top >= height])
    sel = (top > 0.2 * height) & (top < 0.8 * height) & (r >= r_summit)
    slope = np.polyfit(r[sel], top[sel], 1)[0]
    return float(np.degrees(np.arctan(-slope))), float(height)


def test_slumped_cone_stands_at_the_friction_angle(cpu):
    """Angle of repose: a 45 deg cone (R = 12 cells) of cohesionless sand with a constant 30 deg friction
    angle, on a rough floor (separating, Coulomb 1.0 >= tan 30 deg so the base does not slide; notes
    Sec. 6.3), slumps and comes to rest with its flank within +-5 deg of 30 deg (measured 26.1 deg at
    t = 0.5 s).  A 25 deg cone of the same sand does not move (the pile is stable below phi).

    What the friction angle predicts: Mohr-Coulomb gives exactly phi for a cohesionless slope.  The
    Drucker-Prager cone here is matched to Mohr-Coulomb in triaxial compression and is stronger in other
    stress states (up to 44 deg in plane shear for phi = 30 deg), and a slump overshoots the static angle,
    so the measured angle depends on how the pile was made — the measured numbers, for the record:
    the flank creeps slowly (27.2, 26.1, 25.3, 24.4 deg at t = 0.3, 0.5, 1.0, 1.5 s; at dx = 5 mm it does
    not: 26.2, 27.1, 27.5 deg at 0.5, 1.0, 1.5 s, module docstring); phi = 25 deg gives 18 deg, phi = 35 deg 40 deg (the 45 deg cone hardly
    fails); a 55 deg cone falls further and overshoots to ~23 deg (phi = 30 deg); the flank of a squat
    (a = 0.5) collapsed column is only 2-3 cells tall and reads 18-22 deg (resolution-limited: the
    free-surface layer of about one cell is smeared by the B-spline support)."""
    dx, theta0, r_cells = 0.01, 45.0, 12
    o, radius = BOUND * dx, r_cells * dx
    height = radius * np.tan(np.radians(theta0))
    n, nz = BOUND + int(1.5 * r_cells) + 4, BOUND + int(np.ceil(height / dx)) + 3

    def cone(p, h=height):
        r = np.hypot(p[:, 0] - o, p[:, 1] - o)
        return np.maximum(r - (radius - (p[:, 2] - o) * radius / h), o - p[:, 2])

    params = SandParams(hardening=False, h0=30.0)
    walls = DomainWalls.from_dict(
        {"-x": Wall("slip"), "-y": Wall("slip"), "-z": Wall("separate", 1.0)}, default=Wall("separate")
    )
    dt = 0.35 * dx / params.p_wave_speed
    for h in (height, radius * np.tan(np.radians(25.0))):
        body = seed_sdf(lambda p, h=h: cone(p, h), (o, o, o), (o + radius, o + radius, o + h), dx, 2, 0.5, 3)
        sol = SandSolver(cpu, (nz, n, n), dx, dt, params, body.x, body.volume, walls=walls)
        sol.step(int(round(0.5 / dt)))
        x = sol.particles()["x"].astype(np.float64)
        d = sol.diagnostics()
        assert d["kinetic_energy"] < 1e-4 * d["mass"]  # settled: rms speed < 1.4 cm/s
        angle, _ = _flank_angle(x, o, dx)
        if h == height:
            assert angle == pytest.approx(30.0, abs=5.0)
            assert angle < theta0 - 10.0  # it did slump
        else:
            displacement = np.linalg.norm(x - body.x, axis=0)
            assert np.percentile(displacement, 99) < 0.25 * dx  # stable below phi: no flow


def _funnel_pour(cpu, phi: float) -> dict:
    """Fixed-funnel pour (the fixed-funnel angle-of-repose method: sand runs out of a funnel held at a fixed
    height until the heap's tip reaches the orifice).  Quarter domain (slip symmetry planes at -x, -y, the
    heap's axis on their corner), dx = 1 cm, rough floor (separating, Coulomb 1.0 >= tan 35 deg: the base
    does not slide, notes Sec. 6.3).  The funnel is an SDF collider: a conical shell two cells thick,
    inner radius 2 cells at the orifice, 8 cells above the floor, opening at 35 deg from the vertical to
    17 cells above the orifice, walls separating with friction 0.3; it starts full (6848 particles,
    2^3 per cell, more than a 25 deg heap of height 8 cells holds).  E = 1e5 Pa (the paper's time steps
    bound E to ~1e5, params.py) halves the step count of the default sand.

    Flank angle: the mean of the 20-80 % fit of :func:`_flank_angle` over five snapshots at t = 2.0-3.0 s
    (each snapshot alone scatters by about +-1 deg on a heap 7.4 cells tall).  The heap reaches the
    orifice by t = 1.5 s; afterwards the funnel only trickles as fast as the heap's flank creeps away
    (module docstring: the creep)."""
    dx, z_o, r_o, half, depth, thick = 0.01, 8, 2.0, 35.0, 17, 2.0
    o = BOUND * dx
    zo, ro, top = o + z_o * dx, r_o * dx, o + (z_o + depth) * dx
    tn, cs = np.tan(np.radians(half)), np.cos(np.radians(half))
    r_top = ro + depth * dx * tn
    n = BOUND + int(np.ceil(max(r_top / dx + thick / cs + 2, 1.25 * z_o / np.tan(np.radians(phi)) + 3))) + 3
    nz = BOUND + z_o + depth + 4

    def inner(p):  # > 0 outside the funnel's inner cone surface, distance along its normal
        return (np.hypot(p[:, 0] - o, p[:, 1] - o) - ro - (p[:, 2] - zo) * tn) * cs

    def funnel(p, t=0.0):
        shell = np.abs(inner(p) - 0.5 * thick * dx) - 0.5 * thick * dx
        return np.maximum(shell, np.maximum(zo - p[:, 2], p[:, 2] - top))

    def content(p):
        return np.maximum(inner(p), np.maximum(zo - p[:, 2], p[:, 2] - (top - dx)))

    params = SandParams(hardening=False, h0=phi, youngs_modulus=1e5)
    body = seed_sdf(content, (o, o, zo), (o + r_top, o + r_top, top), dx, 2, 0.5, 5)
    walls = DomainWalls.from_dict(
        {"-x": Wall("slip"), "-y": Wall("slip"), "-z": Wall("separate", 1.0)}, default=Wall("separate")
    )
    dt = 0.35 * dx / params.p_wave_speed
    collider = SdfCollider(funnel, mode="separate", friction=0.3)
    sol = SandSolver(cpu, (nz, n, n), dx, dt, params, body.x, body.volume, walls=walls, sdf_collider=collider)
    angles, heights = [], []
    for t in (2.0, 2.25, 2.5, 2.75, 3.0):
        sol.step(int(round(t / dt)) - sol.steps)
        x = sol.particles()["x"].astype(np.float64)
        heap = x[:, x[2] < zo - 0.5 * dx]  # below the orifice (the sand still in the funnel excluded)
        angle, height = _flank_angle(heap, o, dx)
        angles.append(angle)
        heights.append(height / dx)
    d = sol.diagnostics()
    return {
        "angle": float(np.mean(angles)),
        "angles": angles,
        "height_cells": float(np.mean(heights)),
        "left_in_funnel": float(np.mean(x[2] >= zo)),
        "mass0": body.volume.sum() * params.density,
        "mass": d["mass"],
        "in_domain": bool(np.all(np.isfinite(x)) and x[2].min() > o - dx),
    }


@pytest.mark.parametrize(
    "phi",
    [
        pytest.param(25.0, id="phi25"),
        pytest.param(30.0, id="phi30", marks=pytest.mark.slow),
        pytest.param(35.0, id="phi35"),
    ],
)
def test_poured_heap_stands_at_the_friction_angle(cpu, phi):
    """Angle of repose of a POURED heap (fixed-funnel method, :func:`_funnel_pour`) within +-5 deg of the
    friction angle, for constant friction angles of 25 and 35 deg (30 deg: slow).

    The prediction.  A cohesionless Mohr-Coulomb slope stands at phi: on a plane at incipient failure
    tau = sigma_n tan(phi), and an infinite slope of angle beta carries tau / sigma_n = tan(beta) on every
    plane parallel to it.  The Drucker-Prager cone here, ||dev tau|| = 3 alpha p with
    alpha = sqrt(2/3) 2 sin(phi) / (3 - sin(phi)) (mpm_model.cuh; notes Sec. 2.2), circumscribes the
    Mohr-Coulomb pyramid and touches it on the triaxial-compression meridians (sigma_2 = sigma_3), so it
    is as strong as Mohr-Coulomb there and stronger elsewhere: in plane strain with the isochoric
    (deviatoric) flow of the return mapping, sigma_2 = (sigma_1 + sigma_3)/2 and the cone gives
    sin(phi_ps) = 2 sqrt(3) sin(phi) / (3 - sin(phi)): 34.6, 43.9, 55.0 deg for phi = 25, 30, 35.
    (notes Sec. 6.3 guesses the plane-strain cone weaker; it is the stronger one.)  The flank of a
    heap that grows by avalanches spreading outward over a cone extends in the hoop direction, so the hoop
    stress falls to the minor principal stress, the Haar-von Karman closure of axisymmetric granular
    statics with sigma_theta = sigma_3 (Nedderman, Statics and Kinematics of Granular Materials, CUP 1992
    — as recalled, not re-checked): sigma_2 = sigma_3 is triaxial compression, where the cone is
    Mohr-Coulomb.  So the prediction is phi, with phi_ps the ceiling should the hoop stress stay
    intermediate.

    Measured (this test; the heap's height is set by the orifice, 7.4 cells): phi = 25 -> 29.0, 30 -> 34.0,
    35 -> 37.5 deg (mean of the five snapshots; the funnel still holds 0.1 %, 18 %, 36 % of the sand at t = 3 s),
    far below phi_ps. Session 20 (particles that G2P leaves more than a quarter cell inside the funnel's wall are
    pulled back, kernels/mpm_sdf_project.cu) moved these from 27.8, 31.5, 32.1 deg (with 3 %, 20 %, 32 % left),
    closer to phi at 35 deg: sand that had sunk into the funnel's wall at its rim kept trickling onto the heap.
    How long the heap keeps being fed after it chokes mattered at 35 deg before: with a funnel 14 cells deep
    (4062 particles, nearly empty by t = 3 s) the heap stood at 37-38 deg, with this one (17 cells, still
    trickling) at 32 deg.  A fed flank is a slowly flowing surface layer and stands lower: the creep of the
    module docstring.  Resolution matters too: with the
    orifice 6 cells above the floor (heap 5.5 cells tall) phi = 35 reads 27-30 deg (the 20-80 % band is
    3 cells and the smeared free-surface cell eats into it).  A free pour from 12 cells (no choke, the
    jet hits the floor at ~1.5 m/s) stands lower, 20.7 / 28.1 deg for 25 / 35: the impacts flatten it."""
    c = _funnel_pour(cpu, phi)
    assert c["in_domain"]
    assert c["mass"] == pytest.approx(c["mass0"], rel=1e-6)
    assert c["height_cells"] > 7.0  # the heap reached the orifice (8 cells up): a fixed-funnel heap
    assert c["angle"] == pytest.approx(phi, abs=5.0), c["angles"]
    assert max(c["angles"]) - min(c["angles"]) < 4.0  # settled shape, not a passing avalanche


def _block(cpu, saturation: float, t_end: float):
    """Quarter of a 12 x 12 x 12 cm block (slip symmetry walls at -x, -y, friction floor), released at
    t = 0 (the container is gone).  dx = 1.5 cm (4 x 4 x 8 cells for the quarter) and E = 1e5 Pa (the
    paper's time steps bound E to ~1e5, params.py) keep the test short."""
    dx = 0.015
    params = SandParams(youngs_modulus=1e5, density=1600.0)
    o = BOUND * dx
    body = seed_box((o, o, o), (o + 0.06, o + 0.06, o + 0.12), dx, ppc=2, jitter=0.5, seed=2)
    walls = DomainWalls.from_dict(
        {"-x": Wall("slip"), "-y": Wall("slip"), "-z": Wall("separate", 0.5)}, default=Wall("separate")
    )
    dt = 0.35 * dx / params.p_wave_speed
    sol = SandSolver(cpu, (14, 16, 16), dx, dt, params, body.x, body.volume, walls=walls, saturation=saturation)
    sol.step(int(round(t_end / dt)))
    x = sol.particles()["x"]
    return (np.percentile(x[2], 99.5) - o) / 0.12, (np.percentile(x[0], 99.5) - o) / 0.06


def test_wet_block_stands_while_dry_block_collapses(cpu):
    """Paper 000 Fig. 17: with saturation S = 0.1 (cohesion plateau, c_C = 1000 Pa) a 12 cm block stands
    for >= 1 s (height kept within 5 %, no spreading beyond 10 %); dry (S = 0, c_C = 0) it collapses
    (height below 80 % within 0.5 s).  Rankine: the cut needs c_C ~ 400 Pa at phi = 25 deg (params.py)."""
    wet_h, wet_w = _block(cpu, 0.1, 1.0)
    dry_h, dry_w = _block(cpu, 0.0, 0.5)
    assert wet_h > 0.95 and wet_w < 1.10
    assert dry_h < 0.80 and dry_w > 1.3
