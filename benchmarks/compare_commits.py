"""The coupled step of a scene on two commits, measured in one run: per-stage milliseconds per step
(``Simulation.cost_report``) and the ratio old / new.

    python benchmarks/compare_commits.py OLD [NEW] [--scene examples/fig13_sand_drop_beaker_small.toml]
        [--steps 30] [--warm-up 5] [--repeats 3] [--threads 2]

``OLD`` and ``NEW`` are git revisions (``NEW`` defaults to the working tree); each is checked out into a
temporary ``git worktree`` (the working tree is used as it is) and timed in its own subprocess with that
checkout first on ``PYTHONPATH``. The contenders alternate, ``--repeats`` times each, and each stage keeps its
best time: timings on a shared machine drift by up to 3x (DESIGN), a ratio within one run does not.

Compare two commits rather than a commit and the working tree: with the same code on both sides (the working
tree stashed to HEAD), ``HEAD`` against the working tree read the collide-stream 0.85x for the working tree in
session 19 (Fig. 13 small, 1 thread; 0.73x and 0.76x in two runs where only an unrelated kernel differed), while
the other stages agreed. So commit first and name both revisions.

Writes ``benchmarks/results/compare_commits.json``. Kernel libraries are cached by source hash, so the first
repeat of a commit may build them: the ``--warm-up`` steps (not timed) absorb that.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

from _args import int_in

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results"

# run inside each checkout's subprocess: build the scene, warm up, time, print the stage costs as JSON
_CHILD = r"""
import json, sys
from couplekit.scene import Scene
from couplekit.simulation import Simulation
scene, steps, warm = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
sim = Simulation(Scene.load(scene), backend="cpu", log=None)
sim.step(warm)
sim.reset_timing()
sim.step(steps)
rep = sim.cost_report()
print(json.dumps({k: 1e3 * v["mean"] for k, v in rep.items()}))
"""


def _checkout(rev: str | None, tmp: Path, links: list[Path]) -> Path:
    """A checkout of ``rev`` (None: the working tree itself), with the package's two top-level folders
    reachable as couplekit.kernels and couplekit.schedulers (as the editable install maps them); the links it
    makes are appended to ``links``, for the caller to remove (the working tree keeps none)."""
    if rev is None:
        path = ROOT
    else:
        path = tmp / rev.replace("/", "_")
        subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "-q", "--detach", str(path), rev], check=True)
    for name in ("kernels", "schedulers"):
        link = path / "couplekit" / name
        if not link.exists() and not link.is_symlink():
            link.symlink_to(Path("..") / name)
            links.append(link)
    return path


def _time(path: Path, scene: Path, steps: int, warm: int, threads: int) -> dict[str, float]:
    env = dict(os.environ, PYTHONPATH=str(path), OMP_NUM_THREADS=str(threads))
    out = subprocess.run(
        [sys.executable, "-c", _CHILD, str(scene), str(steps), str(warm)],
        cwd=path, env=env, capture_output=True, text=True,
    )  # fmt: skip
    if out.returncode != 0:
        raise RuntimeError(f"timing at {path} failed:\n{out.stderr[-3000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("old", help="git revision timed as 'old'")
    parser.add_argument("new", nargs="?", default=None, help="git revision timed as 'new' (default: working tree)")
    parser.add_argument("--scene", type=Path, default=ROOT / "examples" / "fig13_sand_drop_beaker_small.toml")
    parser.add_argument("--steps", type=int_in(1), default=30)
    parser.add_argument("--warm-up", type=int_in(1), default=5)
    parser.add_argument("--repeats", type=int_in(1), default=3)
    parser.add_argument("--threads", type=int_in(1), default=2)
    parser.add_argument("--out", type=Path, default=RESULTS / "compare_commits.json")
    args = parser.parse_args()
    scene = args.scene.resolve()
    if not scene.is_file():
        parser.error(f"no scene file {scene}")
    for rev in (args.old, args.new):
        if rev is not None and subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--verify", "-q", f"{rev}^{{commit}}"],
                                              capture_output=True).returncode != 0:  # fmt: skip
            parser.error(f"{rev!r} is not a git revision of {ROOT}")

    with tempfile.TemporaryDirectory(prefix="couplekit-compare-") as tmp:
        made, links = [], []
        try:
            paths = {}
            for label, rev in (("old", args.old), ("new", args.new)):
                paths[label] = _checkout(rev, Path(tmp), links)
                if rev is not None:
                    made.append(paths[label])
            best: dict[str, dict[str, float]] = {"old": {}, "new": {}}
            for r in range(args.repeats):
                for label in ("old", "new"):
                    ms = _time(paths[label], scene, args.steps, args.warm_up, args.threads)
                    ms["total"] = sum(ms.values())
                    for k, v in ms.items():
                        best[label][k] = min(best[label].get(k, float("inf")), v)
                    print(f"repeat {r + 1}/{args.repeats} {label}: {ms['total']:.1f} ms/step", flush=True)
        finally:
            for link in links:
                link.unlink(missing_ok=True)
            for p in made:
                subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(p)], check=False)

    stages = sorted(set(best["old"]) | set(best["new"]), key=lambda k: -best["old"].get(k, 0.0))
    ratio = {k: best["old"][k] / best["new"][k] for k in stages if k in best["old"] and best["new"].get(k)}
    result = {
        "command": "python " + " ".join([Path(sys.argv[0]).as_posix(), *sys.argv[1:]]),
        "old": args.old,
        "new": args.new or "working tree",
        "scene": scene.relative_to(ROOT).as_posix() if scene.is_relative_to(ROOT) else str(scene),
        "steps": args.steps,
        "repeats": args.repeats,
        "threads": args.threads,
        "ms_per_step": best,
        "speedup_old_over_new": ratio,
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=1) + "\n")
    print(f"{'stage':28s} {'old ms':>9s} {'new ms':>9s} {'old/new':>8s}")
    for k in stages:
        o, n = best["old"].get(k), best["new"].get(k)
        print(f"{k:28s} {o or 0:9.2f} {n or 0:9.2f} {ratio.get(k, float('nan')):8.2f}")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
