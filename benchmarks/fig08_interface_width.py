"""Fig. 8 at interface width 4: is the 600 kg/m³ ball riding on the water a ball-resolution limit? (issue 16)

One 600 kg/m³ sand ball is thrown into the pool of tests/test_fig08_sand_densities.py (dx = 5 cm, the small
variant's dt and lattice viscosities), its bottom 0.41 m above the surface at 1.4 m/s down, so that it hits
the water at ~3.2 m/s as the small variant's balls do (dropped from rest 0.51 m up). Printed every 0.05 s:
the ball's mean height above the undisturbed surface in ball radii (Archimedes for the small variant's 600
ball: -0.11). Usage::

    PYTHONPATH=. OMP_NUM_THREADS=1 python benchmarks/fig08_interface_width.py XI RADIUS_M [SECONDS]

e.g. ``4 0.087`` (1.74 cells, the paper's ball at this dx), ``4 0.25`` (5 cells), ``8 0.087``. The
domain is 1.0 m along x; 0.6 m along y and 1.6 m tall, or 4.8 radii and 1.8 m for a radius of 0.2 m or more. Results in
docs/examples.md (Fig. 8).
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
import test_fig08_sand_densities as fig08  # noqa: E402  (the test's scene template)

from couplekit.scene import Scene  # noqa: E402
from couplekit.simulation import Simulation  # noqa: E402


def main(xi: float, radius: float, seconds: float = 0.75) -> None:
    big = radius >= 0.2
    width = round(4.8 * radius, 2) if big else 0.6
    zc = fig08.DEPTH + 0.41 + radius
    lz = 1.8 if big else 1.6
    ball = fig08.BALL.format(density=600.0, x=0.5, z=zc, vz=-1.4, r=radius).replace("0.25,", f"{width / 2},")
    text = fig08.SCENE.format(dx=fig08.DX, lx=1.0, lz=lz, depth=fig08.DEPTH, xi=xi, balls=ball)
    text = text.replace("[1.0, 0.5,", f"[1.0, {width},")
    sim = Simulation(Scene.loads(text), backend="cpu", log=None, timing=False)
    every = int(round(0.05 / sim.scene.time.dt))
    for _ in range(int(round(seconds / 0.05))):
        sim.step(every)
        z = sim.particles()["x"][2]
        print(
            f"xi={xi:g} r={radius / fig08.DX:.2f} cells t={sim.time:.2f} s centre-surface={(z.mean() - fig08.DEPTH) / radius:+.2f} r",
            flush=True,
        )


if __name__ == "__main__":
    main(float(sys.argv[1]), float(sys.argv[2]), *(float(a) for a in sys.argv[3:4]))
