"""Copy the PNG previews of the small example runs into docs/gallery and rewrite the gallery section of
docs/examples.md.

    python scripts/make_gallery.py [--runs runs/timing]

Reads the run folders written by ``python benchmarks/example_timings.py`` (one folder per scene, named after
the scene file), takes frames 0, the middle one and the last of each, copies them to ``docs/gallery/`` and
replaces everything between the gallery heading and the next heading of docs/examples.md. Scenes without a
run folder are left out, and so are their old images.
"""

from __future__ import annotations

import argparse
import re
import shutil
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
HEADING = "## Gallery (previews written by `couplekit run` on the small variants)"

CAPTIONS = {
    "sand_drop_small": "Sand drop (the demo)",
    "fig01_outlet_jet_small": "Fig. 1, a water jet from a wall outlet over a sand bed, carrying sand from 0.05 s",
    "fig02_wind_island_small": "Fig. 2, a floating 600 kg/m³ sand ring under a vertical wind",
    "fig03_dam_break_castle_small": "Fig. 3, dam break over a damp sand castle",
    "fig04_colander_small": "Fig. 4, a water–sand jet through a colander into a pool",
    "fig05_bailey_breach_small": "Fig. 5, water poured into a damp sand bailey",
    "fig06_raindrop_small": "Fig. 6, raindrop on sand",
    "fig08_sand_densities_small": "Fig. 8, sand balls of 600, 950 and 1500 kg/m³ dropped into water",
    "fig09_slope_delta_small": "Fig. 9, a sediment-laden flow down a slope and the delta at its foot",
    "fig10_retention_small": "Fig. 10, sand in two openings of a partition wall, retention on one",
    "fig11_stirring_small": "Fig. 11, stirring water and sand",
    "fig12_bunny_dam_break_small": "Fig. 12, a sediment-laden dam break against a rigid bunny (spheres and cylinders)",
    "fig13_sand_drop_beaker_small": "Fig. 13, sand ball into a beaker (obstacles are drawn see-through)",
    "fig14_volume_preservation_small": "Fig. 14, a big sand ball into shallow water",
    "fig15_granular_collapse_small": "Fig. 15, a granular column collapsing into a water layer",
    "fig16_dam_break_sand_small": "Fig. 16, dam break over a sand pile",
    "fig16_dam_break_water_small": "Fig. 16 without sand (water and air)",
    "fig17_wet_column_small": "Fig. 17, water poured on a sand block (retention on)",
    "fig17_dry_column_small": "Fig. 17, the dry sand block",
    "fig18_city_flood_small": "Fig. 18, a flood over a city of boxes, eroding and depositing sand",
}


def frames_of(run: Path) -> list[int]:
    return sorted(int(m.group(1)) for p in run.glob("preview_*.png") if (m := re.match(r"preview_(\d+)\.png", p.name)))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", default=str(ROOT / "runs" / "timing"))
    a = ap.parse_args()
    runs, gallery = Path(a.runs), ROOT / "docs" / "gallery"
    gallery.mkdir(parents=True, exist_ok=True)
    for old in gallery.glob("*.png"):
        old.unlink()
    parts = [HEADING, ""]
    for name, caption in CAPTIONS.items():
        frames = frames_of(runs / name)
        if not frames:
            print(f"no previews for {name} in {runs}: left out")
            continue
        pick = sorted({frames[0], frames[len(frames) // 2], frames[-1]})
        images = []
        for k in pick:
            target = f"{name}_{k:04d}.png"
            shutil.copyfile(runs / name / f"preview_{k:04d}.png", gallery / target)
            images.append(f"![]({gallery.name}/{target})")
        parts += [f"{caption}, frames {', '.join(str(k) for k in pick)}:", "", " ".join(images), ""]
    parts += [
        "These are qualitative pictures of coarse runs, not validations; the physics tests live with the solvers.",
        "",
    ]
    doc = ROOT / "docs" / "examples.md"
    text = doc.read_text()
    start = text.index(HEADING)
    nxt = text.find("\n## ", start + len(HEADING))
    text = text[:start] + "\n".join(parts) + ("\n" + text[nxt + 1 :] if nxt >= 0 else "")
    doc.write_text(text)
    print(f"wrote {len(list(gallery.glob('*.png')))} images to {gallery} and the gallery section of {doc}")


if __name__ == "__main__":
    main()
