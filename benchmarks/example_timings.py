"""Wall time of every small example scene, run the way a user runs it, written to
benchmarks/results/example_timings.json (and printed as the table in docs/examples.md).

    python benchmarks/example_timings.py [--threads 2] [--only fig08 fig16 ...] [--out-dir runs/timing]

Each ``examples/*_small.toml`` (and the demo, ``sand_drop_small.toml``) is run to its ``time.frames`` by
``python -m couplekit run FILE --backend cpu --no-progress`` in a subprocess, one after another, with all
outputs (VTK, PLY, PNG previews, checkpoints) written as in a normal run. Recorded per scene: the exit code,
the wall time of the whole command (Python start-up and kernel builds from a warm cache included), the steps
and frames reached, and from ``diagnostics.jsonl`` the largest lattice speed over the frames and the final
fluid volume drift. Issue #6 asks each small variant to run on 2 CPU cores in under 5 minutes.

Timings are only comparable within one run on an otherwise idle machine: the load average before and after
each scene is recorded with it.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

from _args import int_in

from couplekit.io import read_diagnostics
from couplekit.scene import Scene

ROOT = Path(__file__).resolve().parent.parent
LIMIT_SECONDS = 300.0


def small_scenes() -> list[Path]:
    """The demo first, then every ``*_small.toml`` in ``examples/`` by name."""
    ex = ROOT / "examples"
    return [ex / "sand_drop_small.toml"] + sorted(
        p for p in ex.glob("*_small.toml") if p.name != "sand_drop_small.toml"
    )


def time_scene(scene: Path, out_dir: Path, threads: int) -> dict:
    """Run one scene file to the end in a subprocess and summarise what it did."""
    out = out_dir / scene.stem
    cmd = [sys.executable, "-m", "couplekit", "run", str(scene), "--out", str(out), "--backend", "cpu",
           "--threads", str(threads), "--no-progress", "--overwrite"]  # fmt: skip
    # --overwrite: the folder is this benchmark's own; without it a second run was refused scene by scene
    # (exit 2) and its table showed the first run's diagnostics under a 0 s wall time
    load_before = os.getloadavg()[0]
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    log = out / "diagnostics.jsonl"
    diag = read_diagnostics(log) if log.exists() else []
    last = diag[-1] if diag else {}
    speeds = [d["max_lattice_speed"] for d in diag if "max_lattice_speed" in d]
    # the water's own fastest cell (φ ≥ ½) in lattice units: at 800:1 the fastest cell is often air beside the water
    water_si = [d["max_water_speed"] for d in diag if "max_water_speed" in d]  # two-phase runs only
    water = [Scene.load(scene).units().to_lattice(max(water_si), "velocity")] if water_si else []
    return {
        "scene": scene.name,
        "returncode": proc.returncode,
        "seconds": round(wall, 1),
        "under_5_min": proc.returncode == 0 and wall < LIMIT_SECONDS,
        "frames": int(last.get("frame", 0)),
        "steps": int(last.get("step", 0)),
        "simulated_seconds": last.get("time"),
        "max_lattice_speed": max(speeds) if speeds else None,
        "max_water_lattice_speed": max(water) if water else None,
        "final_fluid_volume_drift": last.get("fluid_volume_drift"),
        "load_average_before": round(load_before, 2),
        "load_average_after": round(os.getloadavg()[0], 2),
        "stderr_tail": proc.stderr.strip().splitlines()[-3:] if proc.returncode else [],
    }


def markdown(rows: list[dict]) -> str:
    lines = [
        "| file | frames | steps | wall time | max lattice speed | of the water | fluid volume drift |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        speed = "–" if r["max_lattice_speed"] is None else f"{r['max_lattice_speed']:.3f}"
        water = "–" if r.get("max_water_lattice_speed") is None else f"{r['max_water_lattice_speed']:.3f}"
        drift = "–" if r["final_fluid_volume_drift"] is None else f"{r['final_fluid_volume_drift']:+.2%}"
        status = "" if r["returncode"] == 0 else f" (exit {r['returncode']})"
        lines.append(
            f"| `{r['scene']}` | {r['frames']} | {r['steps']} | {r['seconds']:.0f} s{status} | {speed} | {water} "
            f"| {drift} |"
        )
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(
        description="Wall time of every small example scene, run the way a user runs it, written to "
        "benchmarks/results/example_timings.json (and printed as the table in docs/examples.md)."
    )
    ap.add_argument("--threads", type=int_in(1), default=2, help="OpenMP threads (default 2, the issue's 2 cores)")
    ap.add_argument("--only", nargs="+", default=None, help="substrings of the scene names to run")
    ap.add_argument("--out-dir", default=str(ROOT / "runs" / "timing"))
    ap.add_argument("--out", default=str(ROOT / "benchmarks" / "results" / "example_timings.json"))
    a = ap.parse_args()
    scenes = small_scenes()
    if a.only:
        unmatched = [k for k in a.only if not any(k in s.name for s in scenes)]
        if unmatched:
            ap.error(f"--only: no small scene matches {', '.join(map(repr, unmatched))}; the scenes: "
                     + ", ".join(s.name for s in scenes))  # fmt: skip
        scenes = [s for s in scenes if any(k in s.name for k in a.only)]
    rows = []
    for scene in scenes:
        r = time_scene(scene, Path(a.out_dir), a.threads)
        rows.append(r)
        print(f"{r['scene']:40s} exit {r['returncode']}  {r['seconds']:7.1f} s  frames {r['frames']:3d}  "
              f"load {r['load_average_before']:.1f}->{r['load_average_after']:.1f}", flush=True)  # fmt: skip
    out = Path(a.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    previous = json.loads(out.read_text()) if out.exists() and a.only else {"scenes": {}}
    previous["scenes"].update({r["scene"]: r for r in rows})
    previous["meta"] = {"threads": a.threads, "machine": platform.platform(), "cpu_count": os.cpu_count(),
                        "python": platform.python_version(), "limit_seconds": LIMIT_SECONDS}  # fmt: skip
    out.write_text(json.dumps(previous, indent=1) + "\n")
    print(markdown(rows))
    if not all(r["under_5_min"] for r in rows):
        sys.exit(1)


if __name__ == "__main__":
    main()
