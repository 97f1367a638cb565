"""``couplekit bench``: Table 1 row by row and the price of each effect, as JSON, PNG plots and markdown
tables under an output folder (default ``benchmarks/results/``), with a progress bar.

* ``quick``: Table 1's rows with a small scene only for Fig. 13 and the coupled-scene effects (minutes);
* full: every row and every effect variant;
* ``tiny``: the test suite's size (scenes coarsened 2x, 10³ effect scene, one step, numpy backend unless
  another is named): checks that everything runs and writes its files, not its timings."""

from __future__ import annotations

import json
import os
import platform
import time
from pathlib import Path

from ..io import files
from . import effects as effects_mod
from . import table1 as table1_mod
from .traffic import assumptions

RESULTS = Path(__file__).resolve().parents[2] / "benchmarks" / "results"
QUICK_FIGURES = [13]
QUICK_EFFECTS = ["surface_tension", "volume_controller", "retention", "smagorinsky", "stirring"]


class _Progress:
    """A one-line text progress bar on stderr (tqdm when installed)."""

    def __init__(self, total: int, enabled: bool = True):
        self.total, self.done, self.enabled, self.t0 = total, 0, enabled, time.perf_counter()

    def __call__(self, label: str) -> None:
        if self.enabled:
            import sys

            width = 30
            fill = int(width * self.done / max(self.total, 1))
            el = time.perf_counter() - self.t0
            sys.stderr.write(
                f"\r[{'#' * fill}{'.' * (width - fill)}] {self.done}/{self.total} {el:5.0f} s  {label:40.40s}"
            )
            sys.stderr.flush()
        self.done += 1

    def close(self) -> None:
        if self.enabled:
            import sys

            sys.stderr.write("\n")


def plot_effects(result: dict, path: Path) -> Path:
    """Horizontal bars: time ratio on/off of each effect (median of the interleaved pairs, the whisker its
    interquartile range; grey where not resolved), annotated with the bytes it allocates."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = [(k, r) for k, r in result["effects"].items() if "unavailable" not in r]
    fig, ax = plt.subplots(figsize=(7, 0.35 * len(rows) + 1.5))
    names = [k for k, _ in rows]
    med = [r["time_ratio_on_off"] for _, r in rows]
    err = [
        [m - r.get("ratio_q1", m) for m, (_, r) in zip(med, rows, strict=True)],
        [r.get("ratio_q3", m) - m for m, (_, r) in zip(med, rows, strict=True)],
    ]
    colors = ["C0" if r.get("resolved", True) else "0.7" for _, r in rows]
    ax.barh(names, med, xerr=err, color=colors, capsize=2)
    for i, (_, r) in enumerate(rows):
        ax.text(r["time_ratio_on_off"], i, f"  {r['allocated_difference'] / 1024:.0f} KiB", va="center", fontsize=7)
    ax.axvline(1.0, color="k", lw=0.8)
    ax.set_xlabel("time per step, effect on / off")
    ax.set_title(f"What each effect costs ({result['cells']} cells, {result['backend']})")
    ax.invert_yaxis()
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def run_bench(
    out: Path | str | None = None,
    quick: bool = False,
    tiny: bool = False,
    backend: str | None = None,
    progress: bool = True,
) -> dict:
    """Run the benchmark set (module docstring) and write ``table1.json``, ``table1.png``, ``table1.md``,
    ``effect_costs.json``, ``effect_costs.png``, ``effect_costs.md`` into ``out``; returns the paths and
    the markdown tables."""
    out = Path(out) if out is not None else RESULTS
    check_writable(out)  # refused before anything is measured; the folder is made only to write the results
    backend = (backend or ("numpy" if tiny else "cpu")).strip().lower()
    figures = QUICK_FIGURES if (quick or tiny) else None
    effect_names = (QUICK_EFFECTS[:2] if tiny else QUICK_EFFECTS) if (quick or tiny) else None
    n_rows = len(figures) if figures else len(table1_mod.TABLE1)
    n_eff = len(effect_names) if effect_names else len(effects_mod.effect_variants(effects_mod.base_scene(8)))
    bar = _Progress(n_rows + n_eff, progress)
    steps, repeats = (1, 1) if tiny else (10, 3)
    machine = {"platform": platform.platform(), "processor": platform.processor() or platform.machine()}
    t1 = table1_mod.run_table1(
        backend, steps, repeats=repeats, coarsen=2.0 if tiny else 1.0, figures=figures, progress=bar
    )
    t1.update({"machine": machine, "projection": assumptions(), "quick": quick, "tiny": tiny})
    ec = effects_mod.run_effect_costs(
        10 if tiny else (24 if quick else 40),
        backend,
        1 if tiny else 4,
        effect_names,
        progress=bar,
        alternations=2 if tiny else 10,
    )
    ec.update({"machine": machine, "quick": quick, "tiny": tiny})
    bar.close()
    md1, md2 = table1_mod.markdown_table(t1), effects_mod.markdown_table(ec)
    writers = {
        "table1.json": lambda p: p.write_text(json.dumps(t1, indent=1, default=str) + "\n"),
        "effect_costs.json": lambda p: p.write_text(json.dumps(ec, indent=1, default=str) + "\n"),
        "table1.md": lambda p: p.write_text(md1 + "\n"),
        "effect_costs.md": lambda p: p.write_text(md2 + "\n"),
        "table1.png": lambda p: table1_mod.plot_table1(t1, p),
        "effect_costs.png": lambda p: plot_effects(ec, p),
    }
    paths = write_all(out, writers)
    return {"paths": paths, "table1_md": md1, "effect_costs_md": md2, "table1": t1, "effect_costs": ec}


def check_writable(out: Path) -> None:
    """OSError, before anything is measured, when the results folder ``out`` cannot be made or written: it is a
    file, lies under a file, or its nearest existing folder is not writable."""
    if out.exists() and not out.is_dir():
        raise NotADirectoryError(f"{out} is a file, not a folder")
    base = out
    while not base.exists():
        base = base.parent
    if not base.is_dir():
        raise NotADirectoryError(f"{base} is a file, not a folder")
    if not os.access(base, os.W_OK | os.X_OK):
        raise PermissionError(f"{base} is not writable")


def write_all(out: Path, writers: dict) -> dict[str, Path]:
    """Write every result of ``writers`` (file name -> function writing that file at the path it is given) into
    ``out`` all or nothing (:func:`couplekit.io.files.write_all`): on any failure or Ctrl-C the results already
    in ``out`` stay as they were and a folder this call made is removed again."""
    paths = {name: out / name for name in writers}
    files.write_all({paths[name]: write for name, write in writers.items()})
    return paths
