"""Plots of a run's diagnostics (``diagnostics.jsonl``) as PNG, and the same quantities of several runs overlaid.

* :func:`plot_run` — ``summary.png``: one panel per quantity the run logged (fluid volume drift, lattice speed
  and Mach, speeds, kinetic energies, sand height and runout, free-surface height, sand steps per step, stage
  costs per frame); panels whose keys are absent are left out, so fluid-only and sand-only runs plot alike.
* :func:`compare_runs` — the same panels with one line per run (a scheduler sweep's points, two commits), and a
  bar chart of the mean cost of each stage per run.
* :func:`load_run` — the readable records of a run folder (:class:`RunLog`); a truncated last line (a run that
  was killed while writing) is skipped and noted, anything else unreadable raises :class:`RunLogError`.

Matplotlib draws through its Agg canvas directly (no pyplot, no display, no global backend switch), so the
plots can be made inside a running simulation or a headless job. ``docs/outputs-plots.md`` describes each
panel.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .files import write_all

__all__ = ["RunLog", "RunLogError", "PANELS", "panels_for", "load_run", "plot_run", "compare_runs", "STAGE_PREFIX"]

STAGE_PREFIX, STAGE_SUFFIX = "stage_", "_ms"
"""Per-frame stage costs are logged as ``stage_<name>_ms`` (mean ms per step over the frame's steps)."""


class RunLogError(ValueError):
    """A run folder's diagnostics cannot be plotted (the message names the folder, what is wrong and the fix)."""


@dataclass
class RunLog:
    """The readable diagnostics of one run folder: ``records`` (one dict per frame, in step order, a frame
    written twice by a resumed run kept once, the later one), ``notes`` (what was skipped, e.g. a truncated last
    line), ``status`` ("done", "diverged", "interrupted" or "" when the folder does not say)."""

    folder: Path
    records: list[dict[str, Any]]
    notes: list[str] = field(default_factory=list)
    status: str = ""

    @property
    def name(self) -> str:
        """The folder's name (the default legend label)."""
        return self.folder.resolve().name or str(self.folder)

    def keys(self) -> set[str]:
        """Every key with at least one finite value."""
        return {k for r in self.records for k, v in r.items() if _finite(v)}

    def series(self, key: str) -> tuple[np.ndarray, np.ndarray]:
        """(time s, value) of ``key`` over the frames that logged it (NaN where a value is not a number)."""
        rows = [r for r in self.records if key in r]
        t = np.array([_number(r.get("time")) for r in rows])  # NaN where the log's time is not a number
        v = np.array([_number(r[key]) for r in rows])
        return t, v

    def stage_names(self) -> list[str]:
        """The stages with a per-frame cost, in the order they first appear (execution order)."""
        names: list[str] = []
        for r in self.records:
            for k in r:
                if k.startswith(STAGE_PREFIX) and k.endswith(STAGE_SUFFIX):
                    n = k[len(STAGE_PREFIX) : -len(STAGE_SUFFIX)]
                    if n not in names:
                        names.append(n)
        return names


def _number(v: Any) -> float:
    try:
        return float(v)
    except (TypeError, ValueError):
        return math.nan


def _finite(v: Any) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)


def load_run(run_dir: str | Path) -> RunLog:
    """The records of ``run_dir/diagnostics.jsonl``. A last line that is not valid JSON (the run was killed
    while writing it) is skipped and noted in :attr:`RunLog.notes`; raises :class:`RunLogError` for a missing
    folder or log, an empty log, or an unreadable line before the last."""
    folder = Path(run_dir)
    if folder.is_file():  # e.g. the run's diagnostics.jsonl itself: the folder holding it is what is meant
        raise RunLogError(
            f"run folder {folder} is a file, not a folder: give the run folder that holds it ({folder.parent})"
        )
    if not folder.is_dir():
        raise RunLogError(
            f"run folder {folder} does not exist: give the folder a run wrote into (couplekit run SCENE --out {folder})"
        )
    log = folder / "diagnostics.jsonl"
    if log.exists() and not log.is_file():
        raise RunLogError(f"{log} is not a file (a folder?): it is not a run's log; give a folder a run wrote into")
    if not log.is_file() and (folder / "run" / "diagnostics.jsonl").is_file():  # a sweep point's folder
        raise RunLogError(
            f"{folder} is a sweep point's folder: its run is in {folder / 'run'}; give that folder instead"
        )
    if not log.is_file():
        raise RunLogError(
            f"run folder {folder} has no diagnostics.jsonl, so there is nothing to plot: is it a run folder? A run "
            "writes one unless its scene sets outputs.diagnostics = false; run the scene again with it on"
        )
    lines = [(i + 1, s) for i, s in enumerate(log.read_text(encoding="utf-8", errors="replace").splitlines())]
    lines = [(n, s) for n, s in lines if s.strip()]
    if not lines:
        raise RunLogError(
            f"{log} is empty: the run stopped before it wrote its first frame; run it again (see its output for why)"
        )
    records, notes = [], []
    for idx, (n, s) in enumerate(lines):
        try:
            rec = json.loads(s)
        except ValueError as exc:
            if idx == len(lines) - 1:
                notes.append(
                    f"{log}: line {n} is cut short (the run stopped while writing it); plotted the {idx} records before it"
                )
                break
            raise RunLogError(
                f"{log}: line {n} is not a JSON object ({exc}); the log was damaged or edited; remove the line, or "
                "run the scene again"
            ) from None
        if not isinstance(rec, dict):  # whole JSON, but not a frame's record: damaged or edited, not cut short
            raise RunLogError(
                f"{log}: line {n} is JSON but not an object (a {type(rec).__name__}); the log was damaged or edited; "
                "remove the line, or run the scene again"
            )
        records.append({k: float(v) if v in ("nan", "inf", "-inf") else v for k, v in rec.items()})
    if not records:
        raise RunLogError(f"{log} holds no readable frame ({notes[0]}); run the scene again")
    by_step: dict[float, dict] = {}
    for r in records:  # a run resumed from an earlier checkpoint writes some frames again: keep the later ones
        by_step[_number(r.get("step", len(by_step)))] = r
    if len(by_step) < len(records):
        notes.append(f"{log}: {len(records) - len(by_step)} frames logged twice (a resumed run); the later kept")
    ordered = [by_step[k] for k in sorted(by_step, key=lambda s: (math.isnan(s), s))]
    return RunLog(folder, ordered, notes, _status(folder))


def _status(folder: Path) -> str:
    """How the run ended, from the newest of the files that end a run (a resumed run that finished leaves an
    older interrupted.h5 behind): diverged.txt, interrupted.h5, checkpoint.h5 (written at the end of a run)."""
    ends = {"diverged.txt": "diverged", "interrupted.h5": "interrupted", "checkpoint.h5": "done"}
    found = [(p.stat().st_mtime_ns, what) for name, what in ends.items() if (p := folder / name).is_file()]
    return max(found)[1] if found else ""


# ---------------------------------------------------------------------------------------------- panels
@dataclass(frozen=True)
class Panel:
    """One plot: ``series`` (key, legend label) drawn against time; drawn when any of its keys was logged.
    ``secondary``: (label, factor) of a right-hand axis that shows the left one times ``factor``."""

    title: str
    ylabel: str
    series: tuple[tuple[str, str], ...]
    log: bool = False
    secondary: tuple[str, float] | None = None
    varying: bool = False
    """Draw only when a value changes from frame to frame (e.g. sand steps per step, 1 throughout in lockstep)."""


PANELS: tuple[Panel, ...] = (
    Panel("Fluid volume drift", "(V - V0) / V0", (("fluid_volume_drift", "fluid volume drift"),)),
    Panel(
        "Largest lattice speed",
        "|u| (lattice units)",
        (("max_lattice_speed", "max lattice speed"),),
        secondary=("Mach", 1.0 / math.sqrt(1.0 / 3.0)),
    ),
    Panel(
        "Largest speed",
        "m/s",
        (
            ("max_speed", "fluid"),
            ("max_water_speed", "water (φ ≥ ½)"),
            ("max_air_speed", "air (φ < ½)"),
            ("sand_max_speed", "sand"),
        ),
    ),
    Panel(
        "Kinetic energy",
        "J",
        (("fluid_kinetic_energy_si", "fluid"), ("sand_kinetic_energy", "sand"), ("total_kinetic_energy_si", "total")),
    ),
    Panel(
        "Sand height and runout", "m", (("sand_top", "pile height (sand_top)"), ("sand_front", "runout (sand_front)"))
    ),
    Panel("Free surface", "mean height (m)", (("free_surface_height", "water surface φ = ½"),)),
    Panel("Sand steps per time step", "sand steps", (("sand_steps_per_step", "mean over the frame"),), varying=True),
)
"""The panels of :func:`plot_run` and :func:`compare_runs`, in order; the stage-cost panel comes last."""


def panels_for(runs: Sequence[RunLog]) -> list[Panel]:
    """The :data:`PANELS` drawn for ``runs``: those with a key some run logged (a ``varying`` one only when its
    values change); the stage-cost panel is added after them when a run logged costs."""
    keys = set().union(*(r.keys() for r in runs))
    out = []
    for p in PANELS:
        if not any(k in keys for k, _ in p.series):
            continue
        if p.varying:
            vals = np.concatenate([r.series(k)[1][1:] for r in runs for k, _ in p.series])  # frame 0: no step yet
            vals = vals[np.isfinite(vals)]
            if vals.size == 0 or np.ptp(vals) == 0:
                continue
        out.append(p)
    return out


def _has_costs(runs: Sequence[RunLog]) -> bool:
    return any(r.stage_names() or "step_seconds" in r.keys() for r in runs)


def _figure(n_panels: int, title: str):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    cols = 1 if n_panels == 1 else 2
    rows = max(1, math.ceil(n_panels / cols))
    fig = Figure(figsize=(6.0 * cols, 3.1 * rows + 0.6), layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(rows, cols, squeeze=False).ravel()
    for ax in axes[n_panels:]:
        ax.set_visible(False)
    fig.suptitle(title, fontsize=11)
    return fig, list(axes[:n_panels])


def _style(ax, panel_title: str, ylabel: str, legend: bool = True) -> None:
    ax.set_title(panel_title, fontsize=10)
    ax.set_xlabel("time (s)")
    ax.set_ylabel(ylabel)
    ax.grid(True, alpha=0.3)
    ax.ticklabel_format(axis="both", style="sci", scilimits=(-3, 4), useMathText=True)
    if legend and ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize=8, loc="best")


def _secondary(ax, panel: Panel) -> None:
    if panel.secondary is not None:
        label, factor = panel.secondary
        sec = ax.secondary_yaxis("right", functions=(lambda y: y * factor, lambda m: m / factor))
        sec.set_ylabel(label)


def _stage_panel_single(ax, run: RunLog) -> None:
    """Stacked per-frame cost of each stage (ms per step), the step's total as a line."""
    names = run.stage_names()
    if names:
        rows = [r for r in run.records if any(STAGE_PREFIX + n + STAGE_SUFFIX in r for n in names)]
        t = np.array([_number(r.get("time")) for r in rows])
        ys = [np.nan_to_num([_number(r.get(STAGE_PREFIX + n + STAGE_SUFFIX, 0.0)) for r in rows]) for n in names]
        order = np.argsort([-float(np.mean(y)) for y in ys])  # the most expensive at the bottom
        top = 9  # more stages than colours are read as one band
        shown = [names[i] for i in order[:top]]
        data = [ys[i] for i in order[:top]]
        if len(names) > top:
            shown.append(f"{len(names) - top} other stages")
            data.append(np.sum([ys[i] for i in order[top:]], axis=0))
        if len(t) > 1:
            ax.stackplot(t, data, labels=shown, alpha=0.85)
        else:  # one timed frame (a 1-frame run): a stack of one point draws nothing, so one stacked bar
            width = 0.5 * abs(float(t[0])) if len(t) and float(t[0]) else 1.0
            bottom = 0.0
            for y, label in zip(data, shown, strict=True):
                ax.bar(t, y, width=width, bottom=bottom, label=label, alpha=0.85)
                bottom = bottom + np.asarray(y)
    elif "step_seconds" in run.keys():
        t, v = run.series("step_seconds")
        ax.plot(t, 1e3 * v, "k.-", label="last step of the frame")
    _style(ax, "Stage costs per frame", "ms per step", legend=False)
    if ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)


def _frame_total_ms(run: RunLog) -> tuple[np.ndarray, np.ndarray]:
    names = run.stage_names()
    if not names:
        t, v = run.series("step_seconds")
        return t, 1e3 * v
    rows = [r for r in run.records if any(STAGE_PREFIX + n + STAGE_SUFFIX in r for n in names)]
    t = np.array([_number(r.get("time")) for r in rows])
    tot = np.array([sum(_number(r.get(STAGE_PREFIX + n + STAGE_SUFFIX, 0.0)) for n in names) for r in rows])
    return t, tot


def _plot_panel(ax, panel: Panel, runs: Sequence[RunLog], labels: Sequence[str] | None) -> None:
    many = labels is not None
    styles = ("-", "--", ":", "-.")
    for j, run in enumerate(runs):
        colour = f"C{j % 10}" if many else None
        for i, (key, what) in enumerate(panel.series):
            if key not in run.keys():
                continue
            t, v = run.series(key)
            if many:
                lab = labels[j] if len(panel.series) == 1 else f"{labels[j]}: {what}"
                ax.plot(t, v, styles[i % len(styles)], color=colour, marker=".", ms=3, label=lab)
            else:
                ax.plot(t, v, marker=".", ms=4, label=what)
    _secondary(ax, panel)
    _style(ax, panel.title, panel.ylabel, legend=many or len(panel.series) > 1)


def _title(run: RunLog) -> str:
    last = run.records[-1]
    frames = int(_number(last.get("frame", len(run.records) - 1)))
    what = f"{run.name}: {frames} frame{'' if frames == 1 else 's'} run, t = {_number(last.get('time')):.4g} s"
    if run.status in ("diverged", "interrupted"):
        what += f" ({run.status})"
    if any("cut short" in n for n in run.notes):
        what += " (last log line cut short, skipped)"
    return what


OTHER_IMAGE_SUFFIXES = (".jpg", ".jpeg", ".pdf", ".svg", ".gif", ".tif", ".tiff", ".bmp", ".webp", ".eps", ".ps")
"""``--out`` suffixes refused: the plots are PNG files, and such a name would otherwise become a folder."""


class PlotOptionError(ValueError):
    """An output path or legend label the plots cannot use; the message names it and the fix."""


def _png_path(out: str | Path, default_name: str) -> Path:
    """The PNG file ``out`` names: ``out`` itself when it ends in .png, else ``out / default_name`` (a folder,
    made when the file is written)."""
    out = Path(out)
    if out.suffix.lower() == ".png":
        return out
    if out.suffix.lower() in OTHER_IMAGE_SUFFIXES and not out.is_dir():
        raise PlotOptionError(f"--out {out}: the plots are PNG images; give a folder, or a path ending in .png")
    return out / default_name


def _save_pngs(figures: dict[Path, Any]) -> None:
    """Each figure as its PNG path, all or none (:func:`couplekit.io.files.write_all`)."""
    write_all({path: lambda p, fig=fig: fig.savefig(p, dpi=100) for path, fig in figures.items()})


def plot_run(run_dir: str | Path, out: str | Path | None = None) -> list[Path]:
    """Draw the diagnostics of the run in ``run_dir`` into ``summary.png`` (in ``out``: a folder, default the
    run folder, or a ``.png`` path). Returns the PNG files written. Panels: :data:`PANELS` that the run logged,
    then the stage costs per frame (stacked, ms per step). Raises :class:`RunLogError` (see :func:`load_run`);
    a truncated last log line is skipped and said so in the figure's title."""
    run = load_run(run_dir)
    panels = panels_for([run])
    costs = _has_costs([run])
    n = len(panels) + int(costs)
    if n == 0:
        raise RunLogError(
            f"{run.folder / 'diagnostics.jsonl'} holds none of the plotted quantities (fluid or sand diagnostics, "
            "stage costs); was it written by couplekit run?"
        )
    fig, axes = _figure(n, _title(run))
    for ax, panel in zip(axes, panels, strict=False):
        _plot_panel(ax, panel, [run], None)
    if costs:
        _stage_panel_single(axes[-1], run)
    path = _png_path(out if out is not None else run.folder, "summary.png")
    _save_pngs({path: fig})
    return [path]


def compare_runs(run_dirs: Sequence[str | Path], out: str | Path, labels: Sequence[str] | None = None) -> list[Path]:
    """Overlay the diagnostics of several runs: ``compare.png`` (the :data:`PANELS` any run logged, one colour
    per run, and each run's total cost per step) and, when the runs logged stage costs, ``compare_stages.png``
    (mean ms per step of each stage, one bar per run). ``out``: a folder, or a ``.png`` path (the stage chart
    then goes next to it as ``<name>_stages.png``). ``labels``: the legend of each run (default the folder
    names; each must be non-empty). Returns the PNG files written, all or none (:func:`_save_pngs`). A stage
    chart an earlier compare left at the same path is removed when these runs logged no stage costs (it would
    show other runs)."""
    main = _png_path(out, "compare.png")  # an unusable --out is refused before any log is read
    runs = [load_run(d) for d in run_dirs]
    if len(runs) < 1:
        raise RunLogError("compare_runs needs at least one run folder")
    if labels is None:
        labels = [r.name for r in runs]
        if len(set(labels)) < len(labels):  # same folder names under different parents
            labels = [str(r.folder) for r in runs]
    elif len(labels) != len(runs):
        raise RunLogError(f"{len(labels)} labels for {len(runs)} run folders: give one label per run")
    labels = list(labels)
    empty = [i + 1 for i, lab in enumerate(labels) if not str(lab).strip()]
    if empty:
        raise PlotOptionError(f"--labels: label {empty[0]} is empty; give every run a label the legend can show")
    panels = panels_for(runs)
    costs = _has_costs(runs)
    n = len(panels) + int(costs)
    if n == 0:
        raise RunLogError("none of the runs logged a plotted quantity (fluid or sand diagnostics, stage costs)")
    notes = [
        lab + f" ({r.status})" for lab, r in zip(labels, runs, strict=True) if r.status in ("diverged", "interrupted")
    ]
    title = f"{len(runs)} runs: " + ", ".join(labels)
    if len(title) > 110:
        title = f"{len(runs)} runs"
    if notes:
        title += "; " + ", ".join(notes)
    fig, axes = _figure(n, title)
    for ax, panel in zip(axes, panels, strict=False):
        _plot_panel(ax, panel, runs, labels)
    if costs:
        ax = axes[-1]
        for j, (run, lab) in enumerate(zip(runs, labels, strict=True)):
            t, v = _frame_total_ms(run)
            if t.size:
                ax.plot(t, v, color=f"C{j % 10}", marker=".", ms=3, label=lab)
        _style(ax, "Cost per time step (all stages)", "ms per step")
    stages_path = (
        main.with_name(main.stem + "_stages.png")
        if Path(out).suffix.lower() == ".png"
        else (main.parent / "compare_stages.png")
    )
    figures = {main: fig}
    if any(r.stage_names() for r in runs):
        figures[stages_path] = _stage_bars(runs, labels)
    _save_pngs(figures)
    if stages_path not in figures:
        stages_path.unlink(missing_ok=True)  # an earlier compare's chart, of other runs
    return list(figures)


def _stage_bars(runs: Sequence[RunLog], labels: Sequence[str]):
    """The figure of the mean ms per step of each stage over the frames, one bar per run (grouped by stage); runs that logged no
    stage costs (logs written before couplekit logged them) are named in the title, not drawn as zeros."""
    without = [lab for r, lab in zip(runs, labels, strict=True) if not r.stage_names()]
    kept = [(j, r, lab) for j, (r, lab) in enumerate(zip(runs, labels, strict=True)) if r.stage_names()]
    colours = [f"C{j % 10}" for j, _, _ in kept]  # each run keeps its colour of compare.png
    runs, labels = [r for _, r, _ in kept], [lab for _, _, lab in kept]
    names: list[str] = []
    for r in runs:
        names += [n for n in r.stage_names() if n not in names]
    means = np.zeros((len(runs), len(names)))
    for j, r in enumerate(runs):
        for i, n in enumerate(names):
            v = r.series(STAGE_PREFIX + n + STAGE_SUFFIX)[1]
            v = v[np.isfinite(v)]
            means[j, i] = float(v.mean()) if v.size else 0.0
    order = np.argsort(-means.max(axis=0))
    names = [names[i] for i in order]
    means = means[:, order]
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(9.0, 1.0 + 0.22 * len(names) * max(1, len(runs)) ** 0.5 + 0.3 * len(runs)),
                 layout="constrained")  # fmt: skip
    FigureCanvasAgg(fig)
    ax = fig.subplots()
    h = 0.8 / len(runs)
    y = np.arange(len(names))
    for j, lab in enumerate(labels):
        ax.barh(y + (j - (len(runs) - 1) / 2) * h, means[j], height=h, color=colours[j], label=lab)
    ax.set_yticks(y, names, fontsize=8)
    ax.invert_yaxis()
    ax.set_xlabel("mean ms per time step over the frames")
    ax.set_title("Stage costs" + (f" (no stage costs logged: {', '.join(without)})" if without else ""), fontsize=10)
    ax.grid(True, axis="x", alpha=0.3)
    ax.legend(fontsize=8, loc="lower right")
    return fig
