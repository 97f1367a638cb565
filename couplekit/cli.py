"""The ``couplekit`` command line.

``couplekit info [--selfcheck] [--backend B]``: version, backend chosen and why, host compiler, nvcc,
CuPy/GPU status, kernel cache; ``--selfcheck`` also builds and runs the self-check kernels against NumPy.

``couplekit validate SCENE``: check a scene file (nothing is allocated); exit 0 when valid, 2 when not, 3 when
``run`` refuses it on any machine (a memory estimate beyond 16 TiB; ``run``'s message). What ``run`` refuses on
this machine (the estimate against the host's available memory, as ``run`` compares it on the cpu and numpy
backends; on cuda it compares with free GPU memory) or for now (a coupling switch) is noted, exit 0; set-ups
admitted but measured to diverge (:func:`couplekit.cautions.stability_cautions`) are printed as ``caution:`` lines,
exit 0.

``couplekit run SCENE [--frames N] [--out DIR] [--backend B] [--resume CKPT] [--scheduler SPEC]``: run a scene
with a progress bar, writing ParaView/PLY/PNG outputs, diagnostics and checkpoints (``--scheduler`` replaces
the scene's ``[scheduler]`` table, e.g. ``subcycle:8``). Exit codes: 0 done, 1 NaN/Inf (the report names
step, field and cell; ``last_good.h5`` is kept), 2 invalid scene, 3 refused (coupled scene,
not enough memory), 130 interrupted by Ctrl-C, 143 by SIGTERM (``interrupted.h5`` written either way; resume
with ``--resume``, which without ``--out`` continues in the folder the checkpoint lies in when that is a run's
folder).

A closed standard output (``couplekit validate scene.toml | head -1``) ends the command quietly, exit 141
(128 + SIGPIPE, as a shell reports a process ended by a closed pipe).

``couplekit sweep SWEEP [--out DIR] [--address HOST:PORT] [--workers N] [--threads N]``: run a sweep file (a
base scene and a grid of dotted-key values, docs/sweeps.md) on Dask; exit 0 when every point finished, 1 when
a point ended in an error, 2 for a malformed sweep file.

``couplekit plot RUN_DIR [--out DIR_OR_PNG]``: draw the diagnostics of a run (``summary.png``, written into
the run folder unless ``--out``; docs/outputs-plots.md). ``couplekit compare RUN_A RUN_B ... [--out DIR_OR_PNG]
[--labels A B ...]``: overlay several runs (``compare.png`` and ``compare_stages.png``, default in the current
folder). Both: exit 0 when the PNGs are written (a log whose last line was cut short by a crash is plotted up
to it, with a note), 2 when a folder, its diagnostics.jsonl or the options are unusable (the message names
the folder and the fix).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from . import __version__
from .backend import BackendUnavailableError, KernelBuildError, KernelCacheError, cuda_status, get_backend, host_tools


def _cmd_info(args: argparse.Namespace) -> int:
    print(f"couplekit {__version__}")
    try:
        backend = get_backend(args.backend, threads=args.threads)
    except (BackendUnavailableError, KernelCacheError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(backend.describe())
    ok, why = cuda_status()
    print(f"cuda: {'available' if ok else 'unavailable'} ({why})")
    for key, value in host_tools().items():
        print(f"{key}: {value}")
    if not args.selfcheck:
        return 0
    if not backend.has_kernels:
        print("selfcheck: the numpy backend compiles no kernels; nothing to check")
        return 0
    from .selfcheck import run_selfcheck

    t0 = time.perf_counter()
    try:
        results = run_selfcheck(backend)
    except KernelCacheError as exc:  # a setting to fix, not a kernel failure
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except KernelBuildError as exc:
        print(f"selfcheck: kernel build failed\n{exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("interrupted: the self-check did not finish (kernels it built stay in the cache)", file=sys.stderr)
        return 130
    for r in results:
        print(
            f"selfcheck {'ok  ' if r.ok else 'FAIL'} {r.name}: rel. error {r.error:.2e} (tolerance {r.tolerance:.0e})"
        )
    if backend.name == "cpu":
        threads = backend.module("selfcheck.cu").num_threads()
        print(f"selfcheck: host kernels ran on {threads} OpenMP thread(s) in {time.perf_counter() - t0:.2f} s")
    return 0 if all(r.ok for r in results) else 1


def _settings(args: argparse.Namespace, scheduler: str | None = None) -> dict:
    """The dotted settings of ``scheduler`` (``run --scheduler``: the ``[scheduler]`` table of
    :func:`couplekit.schedulers.spec_table`) and the ``--set KEY=VALUE`` options of ``args``, in that order (a
    ``--set scheduler.<key>`` applies on top of ``--scheduler``'s table: ``--scheduler subcycle:auto --set
    scheduler.max_substeps=128``)."""
    from .simulation import parse_setting

    settings: dict = {}
    if scheduler is not None:
        from .schedulers import spec_table

        settings["scheduler"] = spec_table(scheduler)  # first: the keys are applied in order
    settings.update(parse_setting(s) for s in args.set)
    return settings


def _load_with_sets(args: argparse.Namespace, scheduler: str | None = None):
    """The scene file of ``args`` with ``scheduler`` and the ``--set`` options applied (:func:`_settings`), validated
    once, as a whole (relative files resolve against the scene file's folder): the scheduler's limits are checked
    with the sand the ``--set`` values give, not the file's. A file that is invalid on its own but valid with the
    settings is taken: the settings are applied to the file's own table and the result validated once (``--set
    time.dt=1e-4`` fixes a file whose time step breaks a limit; validating the file first refused it with the
    value the option replaces).  Errors of the result name the settings."""
    from .scene import Scene, SceneError
    from .scene.schema import read_toml
    from .simulation import apply_settings, with_settings

    settings = _settings(args, scheduler)
    base_dir = Path(args.scene).parent
    try:
        scene = Scene.load(args.scene)
        return with_settings(scene, settings, base_dir=base_dir) if settings else scene
    except SceneError:
        if not settings:
            raise
    data = read_toml(Path(args.scene), SceneError)
    shown = apply_settings(data, settings)
    return Scene.from_dict(data, base_dir=base_dir, source_name=f"{args.scene} with {shown}")


def _viscosity_note(args: argparse.Namespace, scene) -> str | None:
    """A note when ``--set`` changed the time step or the grid spacing of a file whose fluid viscosities are
    lattice numbers (``fluid.water_lattice_viscosity``, Table 1's form, or the default): ν = ν_lattice Δx²/Δt, so
    the run's water and air are then more (or less) viscous than the file's, which a time-step study does not
    want (session 31 found a Δt study of Fig. 17's saturation confounded by it: docs/fluid-stability.md). None
    when the physical viscosities are unchanged or a ``--set`` names a viscosity."""
    from .scene import Scene, SceneError
    from .simulation import parse_setting

    keys = [parse_setting(s)[0] for s in args.set]
    if not any(k.startswith(("time.", "domain.")) for k in keys) or any("viscosity" in k for k in keys):
        return None  # neither Δt nor Δx changed (the file is not read again), or the viscosity is set
    try:
        file_scene = Scene.load(args.scene)
    except (SceneError, OSError):
        return None
    if file_scene.fluid is None or scene.fluid is None:
        return None

    def physical(sc, phase: str) -> float:  # ν = ν_lattice Δx²/Δt
        return sc.units().to_si(getattr(sc.fluid, f"{phase}_lattice_viscosity"), "viscosity")

    phases = ("water", "air") if scene.fluid.phases == 2 else ("water",)
    changed = [p for p in phases if abs(physical(scene, p) - physical(file_scene, p)) > 1e-9 * physical(file_scene, p)]
    if not changed:
        return None
    units = scene.units()  # the file's viscosities in this run's lattice units keep them
    now, then = physical(scene, changed[0]), physical(file_scene, changed[0])
    sets = " ".join(
        f"--set fluid.{p}_lattice_viscosity={units.to_lattice(physical(file_scene, p), 'viscosity'):.6g}"
        for p in changed
    )
    also = f" (the {changed[1]}'s likewise)" if len(changed) > 1 else ""
    return (
        f"note: {args.scene} gives the fluid's viscosities as lattice numbers, so at time.dt = {scene.time.dt:g} s "
        f"and dx = {scene.domain.dx:g} m the {changed[0]}'s is {now:.3g} m²/s, {now / then:.3g}× the file's "
        f"{then:.3g}{also}; to keep the file's viscosities add {sets} (or give the file fluid.water_viscosity and "
        "fluid.air_viscosity in m²/s instead of the lattice numbers)"
    )


def _cmd_validate(args: argparse.Namespace) -> int:
    """Exit 0 valid, 2 invalid, 3 refused with ``run``'s message and exit code: an effect the coupling cannot
    switch off yet, or a memory estimate beyond what any machine holds.  What ``run`` refuses on this machine
    only (its memory) is noted with ``run``'s message, exit 0: the same file validates alike on every host."""
    from .assembly import CouplingUnavailableError, check_odd_ramp_gaps, check_run
    from .cautions import stability_cautions
    from .scene import SceneError
    from .simulation import InsufficientMemoryError, _gib
    from .sweep.keys import KeyPathError

    any_machine = 2.0**44  # 16 TiB: more than the memory of any single host or device couplekit runs on
    try:
        scene = _load_with_sets(args)
    except SceneError as exc:
        print(exc, file=sys.stderr)
        return 2
    except KeyPathError as exc:  # --set: an unknown key
        print(f"error: --set: {exc}", file=sys.stderr)
        return 2
    except ValueError as exc:  # --set: not KEY=VALUE (parse_setting's message names the option)
        print(f"error: {exc}", file=sys.stderr)
        return 2
    est, note = None, None
    try:
        est = check_run(scene)
    except CouplingUnavailableError as exc:  # a property of the scene: refused as run refuses it
        print(f"refused: {exc}", file=sys.stderr)
        return 3
    except InsufficientMemoryError as exc:
        est = exc.estimate
        if est["total"] > any_machine:
            print(f"refused: {exc}", file=sys.stderr)
            return 3
        note = f"note: `run` refuses this scene on this machine: {exc}"
    try:
        check_odd_ramp_gaps(scene)  # what the fluid solver refuses (run's message and exit code 2)
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(f"{args.scene}: valid")
    print(scene.summary())
    speed, why = scene.expected_max_speed()
    units = scene.units()
    if scene.has_fluid:
        print(f"fastest expected flow {speed:.3g} m/s ({why}): lattice Mach {units.mach(speed):.3g}")
    if est is not None:
        print(
            f"memory estimate: {_gib(est['total'])}"
            + (f", about {est['particle_count']:,.0f} particles at most" if est["particle_count"] else "")
        )
    if est is not None:
        from .effect_memory import describe_effect_memory

        print("effects and the memory each costs (FluidX3D's convention, per simulation cell):")
        for line in describe_effect_memory(scene, est.get("particle_count", 0.0)):
            print(line)
    for line in stability_cautions(scene):
        print(f"caution: {line}")
    if note is not None:
        print(note)
    viscosity = _viscosity_note(args, scene)
    if viscosity is not None:
        print(viscosity)
    return 0


def _cmd_bench(args: argparse.Namespace) -> int:
    """Table 1 row by row and the price of each effect (couplekit.bench.runner); prints the tables."""
    from .bench.runner import run_bench

    if args.backend is not None:  # refused before anything is measured or written (the folder included)
        try:
            get_backend(args.backend)
        except (BackendUnavailableError, ValueError) as exc:
            print(f"error: --backend {args.backend}: {exc}", file=sys.stderr)
            return 2
    try:
        res = run_bench(args.out, quick=args.quick, tiny=args.tiny, backend=args.backend, progress=not args.no_progress)
    except OSError as exc:
        print(f"error: cannot write the results to {args.out or 'benchmarks/results'}: {exc}; choose another --out",
              file=sys.stderr)  # fmt: skip
        return 2
    except KeyboardInterrupt:  # run_bench writes all six files or none (bench.runner.write_all)
        print("interrupted: no results written (any results already in the folder are as they were)", file=sys.stderr)
        return 130
    print(res["table1_md"])
    print()
    print(res["effect_costs_md"])
    print("wrote " + ", ".join(str(p) for p in res["paths"].values()))
    return 0


def _run_folder_of(checkpoint: str) -> str | None:
    """The run folder a checkpoint lies in (its folder holds a run's marker, :data:`couplekit.io.outputs.RUN_MARKER`):
    where ``--resume`` without ``--out`` continues, so that a run started with ``--out DIR`` goes on in DIR; None
    for a checkpoint kept elsewhere (then the stored scene's folder)."""
    from pathlib import Path

    from .io.outputs import RUN_MARKER

    folder = Path(checkpoint).parent
    return str(folder) if (folder / RUN_MARKER).is_file() else None


def _drop_made_folder(folder: Path | None) -> None:
    """Remove ``folder`` if it is an empty folder (one this command made before the run was refused)."""
    try:
        if folder is not None and folder.is_dir() and not any(folder.iterdir()):
            folder.rmdir()
    except OSError:
        pass


def _note_scene_file(path: str, stored, checkpoint: str) -> None:
    """A note when the scene file given with --resume is not the checkpoint's scene (changed, invalid or gone):
    the stored scene is the one resumed either way."""
    from .scene import Scene, SceneError

    try:
        same = Scene.load(path).to_dict() == stored.to_dict()
    except (SceneError, OSError, ValueError) as exc:
        lines = [ln.strip() for ln in str(exc).splitlines() if ln.strip()] or [type(exc).__name__]
        why = lines[0].rstrip(":") + (f"; {lines[1].lstrip('- ')}" if len(lines) > 1 else "")
        print(f"note: {path} does not load ({why}); resuming the scene stored in {checkpoint}")
        return
    if not same:
        print(f"note: {path} differs from the scene stored in {checkpoint}; resuming the stored one")


def _cmd_run(args: argparse.Namespace) -> int:
    from .io.checkpoint import CheckpointError
    from .io.outputs import OutputFolderError, default_output, prepare_output
    from .scene import SceneError
    from .simulation import CouplingUnavailableError, InsufficientMemoryError, Simulation
    from .sweep.keys import KeyPathError

    for name in ("frames", "threads"):
        if getattr(args, name) is not None and getattr(args, name) < 1:
            print(f"error: --{name} must be 1 or more, got {getattr(args, name)}", file=sys.stderr)
            return 2
    try:
        if args.scheduler is not None and args.resume:
            print("error: --scheduler cannot change the scheduler of a resumed run (the checkpoint keeps its own)",
                  file=sys.stderr)  # fmt: skip
            return 2
        if args.set and args.resume:
            print(
                "error: --set cannot change a resumed run (the checkpoint keeps its scene: its state belongs to that "
                "scene's time step, grid and solvers); to go on with other settings (a smaller time.dt after a "
                f"divergence, say), run the scene again with them: couplekit run {args.scene} --set KEY=VALUE "
                "--out NEW_DIR",
                file=sys.stderr,
            )
            return 2
        if args.resume:
            # the checkpoint's own scene is resumed: the file need not exist or validate any more (it was edited
            # since, say), and the default output folder is the stored scene's, not the file's
            sim = Simulation.load(args.resume, backend=args.backend, threads=args.threads)
            _note_scene_file(args.scene, sim.scene, args.resume)
            out = prepare_output(
                args.out
                or _run_folder_of(args.resume)
                or sim.scene.outputs.directory
                or default_output(sim.scene.name),
                resume=True,
                overwrite=args.overwrite,
                scene=sim.scene.to_dict(),
                frame=sim.frame,
            )
            print(f"resumed from {args.resume} at step {sim.step_count} (frame {sim.frame})")
        else:
            # --scheduler and --set together, validated once: each alone may be refused where the pair is valid
            # (multirate:2 with a softer sand.youngs_modulus), so neither is checked against the file's other half
            scene = _load_with_sets(args, scheduler=args.scheduler)
            viscosity = _viscosity_note(args, scene)
            if viscosity is not None:
                print(viscosity)
            # the output folder before anything is allocated: a used one is refused unless overwritten, and an
            # earlier run's files are deleted only by sim.run (below), once the run is built: a run refused for
            # memory or an unsupported effect (exit 3), or failing to build, keeps them, and a folder this
            # command made is removed again (_drop_made_folder)
            target = Path(args.out or scene.outputs.directory or default_output(scene.name)).expanduser()
            fresh = None if target.exists() else target
            out = prepare_output(target, resume=False, overwrite=args.overwrite, clear=False)
            try:
                sim = Simulation(scene, backend=args.backend, threads=args.threads)
            except BaseException:
                _drop_made_folder(fresh)
                raise
    except SceneError as exc:
        print(exc, file=sys.stderr)
        return 2
    except KeyPathError as exc:
        print(f"error: --set: {exc}", file=sys.stderr)
        return 2
    except (CouplingUnavailableError, InsufficientMemoryError) as exc:
        print(f"refused: {exc}", file=sys.stderr)
        return 3
    except (BackendUnavailableError, KernelCacheError, CheckpointError, OutputFolderError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:  # the output folder cannot be made: a name too long, a read-only or full disk
        print(f"error: cannot use the output folder: {exc.strerror or exc} ({exc.filename or args.out}); choose "
              "another --out", file=sys.stderr)  # fmt: skip
        return 2
    except KeyboardInterrupt:
        print("interrupted before the run started; nothing to save", file=sys.stderr)
        return 130
    try:
        result = sim.run(frames=args.frames, out=out, progress=not args.no_progress, overwrite=args.overwrite)
    except OutputFolderError as exc:  # e.g. --resume into another run's folder (Simulation.run checks the scene)
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:  # a full disk, a folder removed during the run: what was written stays
        kept = sorted(p.name for p in out.glob("*.h5")) if out.is_dir() else []
        then = (
            f"then --resume {out / kept[-1] if 'checkpoint.h5' not in kept else out / 'checkpoint.h5'} --out {out}"
            if kept
            else "then run it again (no checkpoint was written yet)"
        )
        print(
            f"error: writing the run's outputs into {out} failed ({exc.strerror or exc}); the frames and checkpoints "
            f"written before are kept; free space or choose another --out, {then}",
            file=sys.stderr,
        )
        return 2
    if result.status == "interrupted":
        print(
            f"interrupted ({result.get('signal') or 'stopped'}): checkpoint {result['checkpoint']}; continue with "
            f"--resume {result['checkpoint']} --out {out}"
        )
        return 143 if result.get("signal") == "SIGTERM" else 130
    if result.status == "diverged":
        kept = f"last good state in {result['checkpoint']}" if result["checkpoint"] else "no good state to keep"
        print(f"diverged: {result['error']}; {kept}", file=sys.stderr)
        return 1
    print(f"done: {result['frames']} frames in {result['out']} (checkpoint {result['checkpoint']})")
    return 0


def _cmd_sweep(args: argparse.Namespace) -> int:
    """``couplekit sweep``: exit 0 when every point is final (done, diverged, invalid), 1 when a point ended in
    an error, 2 for a malformed sweep file, bad options, missing dask or an unreachable scheduler, 130 on Ctrl-C."""
    from pathlib import Path

    from .sweep import BACKENDS, DaskUnavailableError, SweepError, is_final, load_sweep, require_dask, run_sweep

    for name in ("workers", "threads"):
        if getattr(args, name) is not None and getattr(args, name) < 1:
            print(f"error: --{name} must be 1 or more, got {getattr(args, name)}", file=sys.stderr)
            return 2
    if args.backend is not None and args.backend not in BACKENDS:
        print(f"error: unknown --backend {args.backend!r}; use one of {', '.join(BACKENDS)}", file=sys.stderr)
        return 2
    try:
        require_dask()
        spec = load_sweep(args.sweep)
    except DaskUnavailableError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except SweepError as exc:
        print(exc, file=sys.stderr)
        return 2
    out = Path(args.out) if args.out else Path("runs") / "sweeps" / spec.name
    try:
        rows = run_sweep(
            spec, out, address=args.address, workers=args.workers, progress=not args.no_progress,
            threads=args.threads, backend=args.backend,
        )  # fmt: skip
    except SweepError as exc:  # e.g. the folder holds another sweep's results (refused before anything is written)
        print(exc, file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(
            f"interrupted: finished points are kept in {out}/points and tabled in {out}/results.*; run the same "
            "command to resume",
            file=sys.stderr,
        )
        return 130
    except OSError as exc:  # an unusable output folder, or the timeout of connecting to --address
        if exc.filename is not None:  # a file operation failed: the folder, not the cluster
            print(f"error: cannot write the sweep's results into {out}: {exc.strerror or exc} ({exc.filename}); "
                  "choose another --out", file=sys.stderr)  # fmt: skip
        else:
            print(f"error: cannot run the sweep on {args.address or 'a LocalCluster'}: {exc}", file=sys.stderr)
        return 2
    failed = [r for r in rows if not is_final(r["status"])]
    if args.no_progress:
        print(f"{spec.name}: {len(rows)} points, {len(failed)} failed; results in {out}")
    if failed:
        names = ", ".join(f"{r['name']} ({r['status']})" for r in failed[:5]) + (" ..." if len(failed) > 5 else "")
        print(f"{len(failed)} point(s) did not finish: {names}; see {out}/points/<id>.json", file=sys.stderr)
        return 1
    return 0


def _cmd_schema(args: argparse.Namespace) -> int:
    """Print the scene JSON Schema, or write it to ``--out`` (exit 0; 2 when the file cannot be written)."""
    from pathlib import Path

    from .scene.jsonschema import render_json

    text = render_json()
    if args.out is None:
        sys.stdout.write(text)
        return 0
    try:
        Path(args.out).write_text(text, encoding="utf-8")
    except OSError as exc:
        print(f"error: cannot write {args.out}: {exc.strerror}; give a writable file path", file=sys.stderr)
        return 2
    print(f"wrote {args.out}")
    return 0


def _cmd_plot(args: argparse.Namespace) -> int:
    """``couplekit plot``: exit 0 when summary.png is written, 2 for an unusable run folder or log."""
    from .io.plots import PlotOptionError, RunLogError, load_run, plot_run

    try:
        for note in load_run(args.run_dir).notes:
            print(f"note: {note}", file=sys.stderr)
        paths = plot_run(args.run_dir, out=args.out)
    except (RunLogError, PlotOptionError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:  # plot_run writes its PNG whole or not at all
        print("interrupted: nothing written", file=sys.stderr)
        return 130
    except OSError as exc:
        print(f"error: cannot write the plot to {args.out or args.run_dir}: {exc}; choose another --out",
              file=sys.stderr)  # fmt: skip
        return 2
    for path in paths:
        print(f"wrote {path}")
    return 0


def _repeats(keys: list) -> list[tuple[int, int]]:
    """(first index, index) of every key equal to an earlier one."""
    first: dict = {}
    return [(first[k], i) for i, k in enumerate(keys) if first.setdefault(k, i) != i]


def _cmd_compare(args: argparse.Namespace) -> int:
    """``couplekit compare``: exit 0 when the PNGs are written, 2 for an unusable run folder, log or option."""
    from .io.plots import PlotOptionError, RunLogError, compare_runs, load_run

    if args.labels is not None and len(args.labels) != len(args.run_dirs):
        print(f"error: {len(args.labels)} --labels for {len(args.run_dirs)} run folders: give one label per run",
              file=sys.stderr)  # fmt: skip
        return 2
    for first, i in _repeats([Path(d).resolve() for d in args.run_dirs]):
        print(f"note: {args.run_dirs[i]} is given twice (runs {first + 1} and {i + 1}): their lines coincide",
              file=sys.stderr)  # fmt: skip
    for first, i in _repeats(args.labels or []):
        if args.labels[i].strip():  # an empty label is refused by compare_runs
            print(f"note: label {args.labels[i]!r} is given to runs {first + 1} and {i + 1}: the legend cannot tell "
                  "them apart", file=sys.stderr)  # fmt: skip
    try:
        for run_dir in args.run_dirs:
            for note in load_run(run_dir).notes:
                print(f"note: {note}", file=sys.stderr)
        paths = compare_runs(args.run_dirs, args.out, labels=args.labels)
    except (RunLogError, PlotOptionError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:  # compare_runs writes its PNGs all or none
        print("interrupted: nothing written", file=sys.stderr)
        return 130
    except OSError as exc:
        print(f"error: cannot write the plots to {args.out}: {exc}; choose another --out", file=sys.stderr)
        return 2
    for path in paths:
        print(f"wrote {path}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of the ``couplekit`` command."""
    parser = argparse.ArgumentParser(prog="couplekit", description=__doc__.split("\n")[0])
    parser.add_argument("--version", action="version", version=f"couplekit {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)

    info = sub.add_parser("info", help="backend, compilers, GPU and cache; --selfcheck runs the kernels")
    info.add_argument("--backend", default="auto", help="auto (default), cuda, cpu or numpy")
    info.add_argument("--threads", type=int, default=None, help="OpenMP threads of the cpu backend")
    info.add_argument("--selfcheck", action="store_true", help="build and run the self-check kernels")
    info.set_defaults(func=_cmd_info)

    validate = sub.add_parser("validate", help="check a scene file (names every bad key and the fix)")
    validate.add_argument("scene", help="scene file (TOML)")
    validate.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="check the scene with this key changed, as run --set would run it (repeatable)",
    )
    validate.set_defaults(func=_cmd_validate)

    bench = sub.add_parser(
        "bench", help="Table 1 of paper 000 row by row and what each effect costs (docs/benchmarks.md)"
    )
    bench.add_argument("--quick", action="store_true", help="a subset: Fig. 13 and five effects (minutes)")
    bench.add_argument(
        "--tiny", action="store_true", help="the test suite's size: runs and writes, timings meaningless"
    )
    bench.add_argument("--out", default=None, metavar="DIR", help="results folder (default benchmarks/results)")
    bench.add_argument(
        "--backend",
        default=None,
        help="cpu (default; numpy with --tiny), cuda, numpy, or cpu-device (the kernels' GPU code paths on the host)",
    )
    bench.add_argument("--no-progress", action="store_true", help="no progress bar")
    bench.set_defaults(func=_cmd_bench)

    run = sub.add_parser("run", help="run a scene: progress bar, VTK/PLY/PNG outputs, diagnostics, checkpoints")
    run.add_argument("scene", help="scene file (TOML)")
    run.add_argument("--frames", type=int, default=None, help="run until this many frames (default: time.frames)")
    run.add_argument("--out", default=None, help="output folder (default: outputs.directory or runs/<name>)")
    run.add_argument("--backend", default="auto", help="auto (default), cuda, cpu or numpy")
    run.add_argument("--threads", type=int, default=None, help="OpenMP threads of the cpu backend")
    run.add_argument(
        "--resume",
        default=None,
        metavar="CKPT",
        help="continue from an HDF5 checkpoint (outputs go on in its run folder unless --out says otherwise)",
    )
    run.add_argument(
        "--scheduler",
        default=None,
        metavar="SPEC",
        help="replace the scene's [scheduler]: lockstep, subcycle[:K|auto][:hold|linear] or multirate:M",
    )
    run.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="set a scene key for this run (repeatable; dotted keys as in sweeps, VALUE a TOML value): "
        "--set outputs.preview=false --set bodies[2].density=900",
    )
    run.add_argument("--no-progress", action="store_true", help="no progress bar")
    run.add_argument(
        "--overwrite",
        action="store_true",
        help="replace the outputs of an earlier run in the output folder (else such a folder is refused)",
    )
    run.set_defaults(func=_cmd_run)

    sweep = sub.add_parser("sweep", help="run a parameter sweep of a scene on Dask (docs/sweeps.md)")
    sweep.add_argument("sweep", metavar="SWEEP", help="sweep file (TOML)")
    sweep.add_argument("--out", default=None, metavar="DIR", help="sweep folder (default runs/sweeps/<name>)")
    sweep.add_argument(
        "--address", default=None, metavar="HOST:PORT", help="a running Dask scheduler (default: a LocalCluster)"
    )
    sweep.add_argument(
        "--workers", type=int, default=None, metavar="N", help="LocalCluster workers (default cores // threads)"
    )
    sweep.add_argument(
        "--threads", type=int, default=None, metavar="N", help="OpenMP threads per point (overrides the file)"
    )
    sweep.add_argument("--backend", default=None, metavar="B", help="auto, cuda, cpu or numpy (overrides the file)")
    sweep.add_argument("--no-progress", action="store_true", help="no line per finished point")
    sweep.set_defaults(func=_cmd_sweep)

    schema = sub.add_parser(
        "schema",
        help="print the scene JSON Schema (for TOML editors: Taplo, Even Better TOML; docs/scene-schema.md)",
    )
    schema.add_argument("--out", default=None, metavar="FILE", help="write it to FILE instead of standard output")
    schema.set_defaults(func=_cmd_schema)

    plot = sub.add_parser("plot", help="draw a run's diagnostics into summary.png (docs/outputs-plots.md)")
    plot.add_argument("run_dir", metavar="RUN_DIR", help="a run's output folder (holds diagnostics.jsonl)")
    plot.add_argument("--out", default=None, metavar="DIR_OR_PNG", help="where to write (default: RUN_DIR)")
    plot.set_defaults(func=_cmd_plot)

    compare = sub.add_parser("compare", help="overlay the diagnostics of several runs (compare.png)")
    compare.add_argument("run_dirs", metavar="RUN_DIR", nargs="+", help="run output folders")
    compare.add_argument(
        "--out", default=".", metavar="DIR_OR_PNG", help="folder or .png path to write (default: the current folder)"
    )
    compare.add_argument("--labels", nargs="+", default=None, metavar="LABEL", help="legend label of each run")
    compare.set_defaults(func=_cmd_compare)

    from .cli_help import add_help_texts

    add_help_texts(parser, sub)  # descriptions, examples and exit codes (couplekit/cli_help.py)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``couplekit`` command. A closed standard output or error (the reader of a pipe
    left, ``| head -1``) ends it quietly with exit 141; a broken pipe of anything else is raised."""
    try:
        args = build_parser().parse_args(argv)
        code = int(args.func(args))
        sys.stdout.flush()  # a pipe's last block is written here, not at exit, so a closed pipe is caught here
        return code
    except BrokenPipeError:
        if not _closed_output():
            raise
        return 141
    except KeyboardInterrupt:  # Ctrl-C before a command's own handler is in place (while modules load)
        print("interrupted before the command started; nothing to save", file=sys.stderr)
        return 130


def _closed_output() -> bool:
    """Whether stdout or stderr is a pipe whose reader has gone (poll reports an error on its write end); each
    such stream is pointed at os.devnull, so that the interpreter's last flush at exit does not fail again."""
    import os
    import select

    closed = False
    for stream in (sys.stdout, sys.stderr):
        try:
            fd = stream.fileno()
        except (AttributeError, OSError, ValueError):  # not a file (e.g. a test's StringIO)
            continue
        if hasattr(select, "poll"):
            poller = select.poll()
            poller.register(fd, select.POLLOUT)
            if not any(event & (select.POLLERR | select.POLLHUP) for _, event in poller.poll(0)):
                continue
        closed = True  # (without poll, a broken pipe reaching here is taken to be this stream's)
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, fd)
        os.close(devnull)
    return closed


if __name__ == "__main__":
    sys.exit(main())
