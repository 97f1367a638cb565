"""Retention with the volume controller on (η = 2, Eq. 52) on paper Fig. 10's dry plug under water
(couplekit.coupling.scenes.dry_plug_under_water, 24 × 8 × 8, R_a = 0.01, ν_h = 1e-3).

History, measured with the same scene (3000 steps, one thread): before commit a7b4d65 ("Eq. 39 next to walls")
this run went NaN at step 2427.  Instrumented every 50 steps, the FIRST field to go bad was the fluid
velocity in the wall-adjacent columns inside the plug (the columns that hold only the B-spline tail of the
sand, ε ≈ 0.09): max |u| sat there from step ~1000 (0.021 at x = 0) while φ went slightly negative at the
bottom wall (−3.8e-5) and free + bound water stayed within 0.01 %; only from step ~2200 did the total drift
(+0.1 %, +0.5 %, +1.7 % by 2400) and γ swing between −2 and 2 every few steps, after which the speed ran away
(0.76 at step 2400).  So γ = −2 turning the absorption sink into a source was a symptom: a controller that
sees volume appearing from a growing wall-column flow fights it with the only lever it has.  The cause was
Eq. 39's porosity-slip term next to walls, fixed in the fluid (a7b4d65).  Since then the same run stays finite
to 8000 steps (max |u| 0.016 at step 3000, 0.108 at step 8000 in a wall corner, free + bound water
−0.07 %), γ settles near 0 once the plug's surface nodes are at capacity (then ε̃ S_φ ≈ −(1 − φ) dR is
tiny and γ has nothing to correct).  Also at R_a = 0.001: finite to 5000 steps, max |u| 0.018.
"""

from __future__ import annotations

import numpy as np

from couplekit.coupling.scenes import dry_plug_under_water

STEPS = 3000


def test_retention_with_volume_controller_runs_past_former_divergence(cpu1):
    """3000 steps at η = 2 (the former NaN at step 2427): finite, max lattice speed < 0.05 (measured
    0.0158–0.035; the 0.05 is the coupled scenes' small-speed bound, well under the 0.76 of the runaway),
    bound water ≤ r_max ε on every node (Eq. 55's capacity; 1e-6 relative for float32), and free + bound
    water conserved to 1 % (measured 8.4e-4, mostly the first 600 steps while γ sat at 2)."""
    sc = dry_plug_under_water(cpu1, retention=True, absorption_rate=0.01, nu_h=1e-3, youngs_modulus=1e5,
                              eta=2.0, sand_params={"cohesion_max": 0.0})  # fmt: skip
    assert sc.fluid.params.eta == 2.0
    sc.step(1)  # the coupler's first step sets the porosity (at construction ε̃ ≡ 1)
    w0 = sc.water_volume()
    be = sc.fluid.backend
    worst, gammas = 0.0, []
    for _ in range(STEPS // 100):
        sc.step(100)
        assert sc.finite()
        worst = max(worst, sc.max_lattice_speed())
        gammas.append(sc.fluid.gamma)
    assert worst < 0.05, worst
    fields = sc.coupler.fields()
    bound = fields["bound_water"].astype(np.float64)
    cap = sc.coupler.params.r_max * fields["sand_fraction"].astype(np.float64)
    assert (bound <= cap * (1 + 1e-6) + 1e-7).all(), float((bound - cap).max())
    assert bound.sum() > 20.0, "the plug must actually bind water (measured 29.7 cells)"
    drift = sc.water_volume() / w0 - 1
    print(f"max speed {worst:.4f}, bound {bound.sum():.2f}, drift {drift:.2e}, gamma {np.round(gammas, 2)}")
    assert abs(drift) < 0.01, drift
    assert np.isfinite(be.to_host(sc.coupler.moisture_ratio)).all()


def test_retention_and_controller_conserve_water_on_the_partition_bed(cpu1):
    """The wetting-front benchmark's bed under a partition wall (20 × 8 × 48, bed 5 cells, R_a = 0.01, η = 2),
    the run that created 2.7 % water by step 8000 before session 3's fixes of Eq. 39's slip term (measured
    then with benchmarks/wetting_front.py: the controller's lever Σ ε̃ S_φ fell to ~1e-5 cell volumes and γ
    flipped between ±2). Since then it conserves free + bound water (benchmark, 8000 steps: +9.6e-4).
    Asserted over 3000 steps: within 2e-3, and steady, changing by at most 1e-4 after step 1000 (measured
    +9.4e-4 at step 3000, +3e-5 after step 1000)."""
    from couplekit.coupling.scenes import bed_under_partition

    sc = bed_under_partition(cpu1, (20, 8, 48), retention=True, absorption_rate=0.01, nu_h=1e-3, eta=2.0,
                             youngs_modulus=1e5, sand_params={"cohesion_max": 0.0}, bed=5.0, partition=(10.0, 38.0),
                             partition_top=16.0, water_top=15.0)  # fmt: skip
    sc.step(1)
    w0 = sc.water_volume()
    drift = []
    for _ in range(30):
        sc.step(100)
        drift.append(sc.water_volume() / w0 - 1)
    print("drift every 100 steps", np.round(drift, 5))
    assert sc.finite()
    assert np.abs(drift).max() < 2e-3, drift
    assert abs(drift[-1] - drift[9]) < 1e-4, drift
