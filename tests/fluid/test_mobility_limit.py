"""How much mobility a moving interface needs at 800:1 (session 32): `couplekit.cautions.mobility_caution`.

The conservative phase field keeps its profile by the mobility's sharpening flux (∝ M/ξ); a flow that strains the
interface faster tears it, φ leaves [0, 1] and the density jump diverges. Measured on the water ball of
couplekit.fluid.interface_cases, thrown at a wall (``at_wall``, 600 steps) or moving through open air (1000 steps),
lattice speed u and mobility M (✓ ran, ✗ diverged; u/M in brackets; `python benchmarks/mobility_map.py`, its
results in benchmarks/results/mobility_map.json):

==========  =======================================================  ==========================================
width       hitting a wall                                           through open air
==========  =======================================================  ==========================================
2.5         M 0.04: ✓ 0.08 (2), ✗ 0.11; 0.02: ✓ 0.02 (1), ✗ 0.04   M 0.04: ✓ 0.08, ✗ 0.11; 0.02: ✓ 0.04,
            (2); 0.01 and below: ✗ 0.02 (2)                          ✗ 0.08 (4); 0.01: ✓ 0.02, ✗ 0.04 (4);
                                                                     0.005: ✗ 0.02
3           M 0.04: ✓ 0.11 (2.75); 0.02: ✓ 0.04, ✗ 0.08 (4);       M 0.04: ✓ 0.08; 0.02: ✓ 0.08, ✗ 0.11;
            0.01: ✓ 0.02, ✗ 0.04 (4); 0.005, 0.0025: ✗ 0.02 (4, 8)  0.01: ✓ 0.04, ✗ 0.08 (8); 0.005: ✗ 0.04
4           M 0.04: ✓ 0.11; 0.02: ✓ 0.08 (4), ✗ 0.11 (5.5);         M 0.04, 0.02: ✓ 0.11; 0.01: ✓ 0.08 (8),
            0.01: ✓ 0.04, ✗ 0.08 (8); 0.005: ✓ 0.02, ✗ 0.04 (8);    ✗ 0.11 (11); 0.005: ✓ 0.04, ✗ 0.08 (16);
            0.0025: ✗ 0.02 (8)                                        0.0025: ✓ 0.02, ✗ 0.04 (16)
5           M 0.04, 0.02: ✓ 0.11 (5.5); 0.01: ✓ 0.04, ✗ 0.08 (8);   M 0.02, 0.04: ✓ 0.11; 0.01: ✓ 0.08, ✗ 0.11;
            0.005: ✓ 0.02, ✗ 0.04 (8); 0.0025: ✗ 0.02 (8)           0.005, 0.0025: ✓ 0.04, ✗ 0.08 (16, 32)
6           M 0.04, 0.02: ✓ 0.11; 0.01: ✓ 0.08 (8), ✗ 0.11 (11);   every M ≥ 0.005 ✓ to 0.11 (22);
            0.005: ✓ 0.04, ✗ 0.08 (16); 0.0025: ✓ 0.02, ✗ 0.04 (16) 0.0025: ✓ 0.08 (32), ✗ 0.11 (44)
8           M 0.04, 0.02: ✓ 0.11; 0.01: ✓ 0.08, ✗ 0.11 (11);       as width 6
            0.005: ✓ 0.04, ✗ 0.08; 0.0025: ✓ 0.04 (16), ✗ 0.08 (32)
==========  =======================================================  ==========================================

So the limit is mostly a ratio u/M that grows with the width (width 4: a wall impact runs to 4 and diverges from
5.5; open air twice that), with a speed limit of its own at the widest (width 8, u/M = 16 ran at 0.04 and diverged
at 0.08). A two-relaxation-time phase-field collision (Λ = 1/6, as with an inflow) moved it little: at width 4
the wall impact ran at u = 0.04 with M = 0.005 and 0.0025 but still diverged at 0.08 with M = 0.01, and the open-air
ball diverged at M = 0.01, u = 0.08 where the single rate runs (measured, not adopted). The examples' own
(M, width) = (0.02, 4) run flows expected up to u/M = 8.1 (the speed estimates are upper bounds), so the caution
speaks only where a scene lowers the mobility or narrows the interface. On a case the limits were not measured
on, Fig. 6's raindrop (expected u/M = 7.6): it runs at M = 0.02, diverges by step 70 at M = 0.01 and 0.0075 and at
width 3, and at Δt/4 with M = 0.005 (the physical mobility of its file kept), each cautioned; it also runs at Δt/2
with M = 0.01 (u/M 7.6, cautioned: the caution is an upper bound).
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from couplekit.cautions import EXAMPLE_MOBILITY, MOBILITY_IMPACT_LIMITS, mobility_caution, stability_cautions
from couplekit.fluid.interface_cases import ball, steps_to_diverge
from couplekit.scene import Scene
from couplekit.simulation import Simulation, SimulationDiverged, with_settings

ROOT = Path(__file__).resolve().parents[2]
RAINDROP = ROOT / "examples" / "fig06_raindrop_small.toml"


@pytest.mark.parametrize(
    "width,mobility,speed,runs",
    [
        (4.0, 0.005, 0.02, True),
        (4.0, 0.005, 0.04, False),
        (4.0, 0.02, 0.08, True),
        (4.0, 0.01, 0.08, False),
        (6.0, 0.005, 0.04, True),
        (3.0, 0.02, 0.08, False),
    ],
    ids=["w4_M.005_u.02", "w4_M.005_u.04", "w4_M.02_u.08", "w4_M.01_u.08", "w6_M.005_u.04", "w3_M.02_u.08"],
)
def test_a_water_ball_hitting_a_wall_needs_a_mobility_that_grows_with_its_speed(width, mobility, speed, runs):
    """Points of the map on both sides of the limit: at width 4 halving M halves the speed that runs (u/M = 4
    runs, 8 diverges), and a wider interface runs the same M faster (width 6: u/M = 8 runs). A diverging run goes
    within 300 steps (measured 100-220); a running one stays under 2.5× its speed (measured up to 2.36×: the
    impact's splash, 0.189 at u = 0.08)."""
    diverged, peak, _ = steps_to_diverge(ball(width, speed, mobility=mobility, at_wall=True), steps=600)
    if runs:
        assert diverged is None, f"diverged by step {diverged}"
        assert peak < 2.5 * speed, peak / speed
    else:
        assert diverged is not None and diverged <= 300, diverged


@pytest.mark.parametrize("radius", [4.0, 8.0])
def test_the_limit_is_the_same_for_a_smaller_and_a_larger_ball(radius):
    """The ratio, not the ball's size in cells: at width 4 and M = 0.005 balls of radius 4 and 8 cells (6 in the
    map) run at u = 0.02 and diverge at 0.04 (by step 220, measured for both; at M = 0.02, u = 0.08 both run and
    at M = 0.01 they diverge, by steps 160 and 120). Only the verdict is asked: the 8-cell ball's splash in this box
    peaks at 5× its speed."""
    assert steps_to_diverge(ball(4.0, 0.02, mobility=0.005, at_wall=True, radius=radius), steps=600)[0] is None
    diverged = steps_to_diverge(ball(4.0, 0.04, mobility=0.005, at_wall=True, radius=radius), steps=600)[0]
    assert diverged is not None and diverged <= 300, diverged


def test_the_caution_reads_the_measured_map():
    """:data:`MOBILITY_IMPACT_LIMITS` is what benchmarks/results/mobility_map.json measured for the wall impact:
    per width the smallest u/M that diverged, and the largest u/M below it that ran (so every run at or below it
    ran); neither falls as the interface widens."""
    runs = json.loads((ROOT / "benchmarks" / "results" / "mobility_map.json").read_text())["runs"]
    for width, (ran, diverged) in MOBILITY_IMPACT_LIMITS.items():
        mine = [r for r in runs if r["kind"] == "wall" and r["width"] == width]
        assert mine, f"width {width} not in the map"
        first_diverged = min(r["speed"] / r["mobility"] for r in mine if not r["ran"])
        last_ran = max(
            r["speed"] / r["mobility"] for r in mine if r["ran"] and r["speed"] / r["mobility"] < first_diverged
        )
        assert (last_ran, first_diverged) == pytest.approx((ran, diverged)), width
    widths = sorted(MOBILITY_IMPACT_LIMITS)
    for w in widths:
        ran, diverged = MOBILITY_IMPACT_LIMITS[w]
        assert 0 < ran < diverged, w
    for a, b in zip(widths, widths[1:], strict=False):
        assert MOBILITY_IMPACT_LIMITS[a][0] <= MOBILITY_IMPACT_LIMITS[b][0], (a, b)
        assert MOBILITY_IMPACT_LIMITS[a][1] <= MOBILITY_IMPACT_LIMITS[b][1], (a, b)


def test_the_caution_names_a_low_mobility_against_a_fast_flow_and_only_then():
    """The caution (validate prints it, a run logs it) names the key, u/M, the measurement and a time step that
    brings u/M to the running ratio; none at the examples' (M, width), at a higher mobility or a wider interface,
    below 400:1, in a single-phase fluid, or where the expected flow is slow for the mobility."""
    (c,) = mobility_caution(Scene.from_dict(ball(4.0, 0.04, mobility=0.005, at_wall=True)))
    assert "fluid.mobility = 0.005" in c and "u/M = 12" in c and "diverged from 5.5" in c, c  # 1.5 × 0.04 / 0.005
    assert "lower time.dt to <= 0.000333 s" in c, c  # dt × 4 / 12
    (c,) = mobility_caution(Scene.from_dict(ball(3.0, 0.06, at_wall=True)))
    assert "fluid.interface_width = 3" in c and "fluid.mobility" not in c.split(" with ")[0], c
    assert mobility_caution(Scene.from_dict(ball(4.0, 0.08, at_wall=True))) == []  # the examples' M and width
    assert mobility_caution(Scene.from_dict(ball(4.0, 0.08, mobility=0.04, at_wall=True))) == []
    assert mobility_caution(Scene.from_dict(ball(6.0, 0.04, mobility=0.01, at_wall=True))) == []  # u/M 6 < 11
    assert mobility_caution(Scene.from_dict(ball(4.0, 0.02, mobility=0.01, at_wall=True))) == []  # u/M 3 < 5.5
    assert mobility_caution(Scene.from_dict(ball(4.0, 0.04, ratio=400.0, mobility=0.005, at_wall=True))) == []
    assert mobility_caution(Scene.from_dict(ball(2.0, 0.04, mobility=0.005, at_wall=True))) == []  # the narrow one's
    one_phase = ball(4.0, 0.04, mobility=0.005)
    one_phase["fluid"] = {"phases": 1, "mobility": 0.005}
    one_phase["bodies"] = []
    assert mobility_caution(Scene.from_dict(one_phase)) == []


def test_the_raindrop_diverges_where_cautioned_and_runs_where_not():
    """A case the limits were not measured on: Fig. 6's small raindrop (a 2 mm drop at 1.5 m/s onto a sand bed,
    expected lattice speed 0.15). At M = 0.01 it diverges by step 70 (measured; 100 steps run here), and
    ``stability_cautions`` named it before the run; at the file's M = 0.02 it runs those steps uncautioned."""
    for mobility, runs in ((0.01, False), (EXAMPLE_MOBILITY, True)):
        scene = with_settings(RAINDROP, {"fluid.mobility": mobility})
        assert any("fluid.mobility" in c for c in stability_cautions(scene)) is not runs
        sim = Simulation(scene, backend="cpu", threads=1, log=None)
        sim.step(100)
        if runs:
            sim.check_finite()
        else:
            with pytest.raises(SimulationDiverged):
                sim.check_finite()
