"""Previews colour wet sand darker than dry (paper 000 §5.1): by retained water r_p on a fixed scale with
retention, by the wet/dry classification S_r,p > (1 − ε_max)/2 without; speed colouring stays available."""

from __future__ import annotations

import numpy as np
import pytest

from couplekit import Scene, Simulation
from couplekit.io.preview import render_preview
from tests.scene.sim_scenes import tiny_coupled, tiny_sand

pytest.importorskip("pyvista")


def _rgb(hex_colour: str) -> np.ndarray:
    return np.array([int(hex_colour[i : i + 2], 16) for i in (1, 3, 5)], float)


def _pixels_near(png, colour: str, tol: float = 40.0) -> int:
    import matplotlib.image as mpimg

    img = mpimg.imread(png)[..., :3] * 255.0
    return int((np.linalg.norm(img - _rgb(colour), axis=-1) < tol).sum())


def _sand_brightness(png) -> float:
    """Mean brightness of the brownish (sand) pixels of a preview: r > g > b by a margin; the white
    background, the black outline, grey labels, the legend and the colour bar are left out."""
    import matplotlib.image as mpimg

    img = mpimg.imread(png)[..., :3] * 255.0
    h, w = img.shape[:2]
    img = img[int(0.2 * h) :, : int(0.84 * w)]  # not the legend (upper left) nor the colour bar (x > 0.86)
    r, g, b = img[..., 0], img[..., 1], img[..., 2]
    sand = (r > g + 5) & (g > b + 5) & (r - b > 25)
    assert sand.sum() > 200, "no sand drawn"
    return float(img[sand].mean())


def _cloud(n: int = 300):
    rng = np.random.default_rng(0)
    return rng.uniform([0.2, 0.2, 0.1], [0.8, 0.8, 0.5], (n, 3)).T


def _render(tmp_path, name, particles, **kw):
    try:
        return render_preview(tmp_path / name, (1.0, 1.0, 1.0), 0.1, {}, particles, **kw)
    except Exception as exc:  # no EGL/OSMesa library on this machine
        pytest.skip(f"off-screen rendering unavailable: {exc}")


def test_wet_sand_is_drawn_darker_than_dry_without_retention(tmp_path):
    x = _cloud()
    n = x.shape[1]
    at_rest = np.zeros_like(x)
    wet = {"x": x, "v": at_rest, "wetness": np.full(n, 0.9, np.float32)}
    dry = {"x": x, "v": at_rest, "wetness": np.full(n, 0.1, np.float32)}
    b_wet = _sand_brightness(_render(tmp_path, "wet.png", wet, colour_by="wetness"))
    b_dry = _sand_brightness(_render(tmp_path, "dry.png", dry, colour_by="wetness"))
    assert b_wet < 0.6 * b_dry
    # just below and above the paper's threshold S = (1 - eps_max)/2 (wetness 1/2): dry, then wet
    b_below = _sand_brightness(
        _render(tmp_path, "b.png", {**dry, "wetness": np.full(n, 0.49, np.float32)}, colour_by="wetness")
    )
    b_above = _sand_brightness(
        _render(tmp_path, "a.png", {**dry, "wetness": np.full(n, 0.51, np.float32)}, colour_by="wetness")
    )
    assert b_below == pytest.approx(b_dry, rel=0.02) and b_above == pytest.approx(b_wet, rel=0.02)
    # coloured by speed, wet and dry sand at rest look alike
    s_wet = _sand_brightness(_render(tmp_path, "sw.png", wet, colour_by="speed", speed_range=(0.0, 1.0)))
    s_dry = _sand_brightness(_render(tmp_path, "sd.png", dry, colour_by="speed", speed_range=(0.0, 1.0)))
    assert s_wet == pytest.approx(s_dry, rel=0.02) and s_dry == pytest.approx(b_dry, rel=0.05)


def test_retained_water_uses_the_fixed_scale_0_to_r_max(tmp_path):
    """r_p = r_max is drawn as dark as the wet classification, r_p = 0 as light as dry sand, and r_max/2 in
    between, whatever the other particles of the frame hold: the scale is the run's (0 to r_max), not the
    frame's."""
    x = _cloud()
    n = x.shape[1]
    base = {"x": x, "v": np.zeros_like(x), "wetness": np.zeros(n, np.float32)}

    def bright(name, r):
        png = _render(tmp_path, name, {**base, "moisture": np.full(n, r, np.float32)}, colour_by="wetness",
                      moisture_max=0.28)  # fmt: skip
        return _sand_brightness(png)

    b0, b_half, b_full = bright("0.png", 0.0), bright("h.png", 0.14), bright("1.png", 0.28)
    b_classified = _sand_brightness(_render(tmp_path, "c.png", {**base, "wetness": np.ones(n, np.float32)},
                                            colour_by="wetness"))  # fmt: skip
    assert b_full < b_half < b0 and b_full < 0.6 * b0
    assert b_full == pytest.approx(b_classified, rel=0.03)


def test_unknown_colouring_is_refused(tmp_path):
    with pytest.raises(ValueError, match="colour_by must be one of"):
        render_preview(tmp_path / "x.png", (1.0, 1.0, 1.0), 0.1, {}, {}, colour_by="moisture")


@pytest.mark.parametrize(
    "scene, choice, expected",
    [
        (lambda: tiny_coupled(retention=True), "auto", ("wetness", 0.28)),
        (lambda: tiny_coupled(retention=False), "auto", ("wetness", None)),
        (lambda: tiny_coupled(retention=True), "speed", ("speed", None)),
        (tiny_sand, "auto", ("speed", None)),
        (tiny_sand, "wetness", ("wetness", None)),
    ],
)
def test_simulation_picks_the_colouring_from_the_scene(scene, choice, expected):
    d = scene()
    d.setdefault("outputs", {})["preview_colour"] = choice
    sim = Simulation(Scene.from_dict(d), backend="numpy", log=None)
    mode, r_max = sim.preview_colouring()
    assert mode == expected[0]
    assert r_max == pytest.approx(expected[1]) if expected[1] is not None else r_max is None


def test_bad_preview_colour_is_refused_by_the_scene():
    d = tiny_sand()
    d.setdefault("outputs", {})["preview_colour"] = "rainbow"
    with pytest.raises(Exception, match="preview_colour"):
        Scene.from_dict(d)
