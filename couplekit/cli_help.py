"""The help texts of the ``couplekit`` command: what each subcommand does, examples to copy, and exit codes.

Plain text (argparse shows it as written: no reStructuredText markup), set on the parsers by
:func:`add_help_texts` after :func:`couplekit.cli.build_parser` has built them.
"""

from __future__ import annotations

import argparse

__all__ = ["DESCRIPTIONS", "EXAMPLES", "EXIT_CODES", "add_help_texts"]

_CLOSED = "standard output closed (the reader of a pipe left: couplekit validate scene.toml | head -1)"

EXIT_CODES: dict[str, dict[int, str]] = {
    "": {
        0: "success: done, valid, printed",
        1: "run: NaN/Inf in the state; sweep: a point ended in an error; info --selfcheck: a kernel failed",
        2: "invalid scene or sweep file (every problem names the dotted key and the fix), or a bad option",
        3: "refused: not enough memory for the scene, or an effect the coupling cannot switch off yet",
        130: "interrupted by Ctrl-C (run: continue with --resume; sweep: run the same command)",
        141: _CLOSED,
    },
    "info": {
        0: "done; with --selfcheck, every kernel agrees with the NumPy reference",
        1: "--selfcheck: a kernel failed to build or disagrees with NumPy",
        2: "the backend asked for is unavailable, the kernel cache folder is unusable, or a bad option",
        130: "interrupted by Ctrl-C (kernels already built stay in the cache)",
        141: _CLOSED,
    },
    "validate": {
        0: "valid (what run refuses on this machine only, for its memory, is noted)",
        2: "invalid: every problem, each with its dotted key and the fix",
        3: "refused as run refuses it on any machine: an estimate beyond 16 TiB, or a coupling switch",
        141: _CLOSED,
    },
    "run": {
        0: "done: every frame written, checkpoint.h5 at the end",
        1: "NaN/Inf: the report names step, field and cell; last_good.h5 and diverged.txt are written",
        2: "invalid scene, bad option, an output folder of another run (--overwrite), unreadable checkpoint",
        3: "refused: the memory estimate exceeds 90 % of the free memory, or an effect the coupling cannot "
        "switch off yet",
        130: "interrupted by Ctrl-C: interrupted.h5 written, continue with --resume",
        141: _CLOSED,
    },
    "sweep": {
        0: "every point finished (done, diverged or invalid)",
        1: "a point ended in an error (its record: points/<id>.json in the sweep folder)",
        2: "malformed sweep file, bad option, dask missing, or the scheduler at --address unreachable",
        130: "interrupted by Ctrl-C: finished points are kept, the same command resumes",
        141: _CLOSED,
    },
    "plot": {
        0: "summary.png written (a cut-short last line of the log is skipped, with a note)",
        2: "no such run folder, no or unreadable diagnostics.jsonl, or the PNG cannot be written",
        130: "interrupted by Ctrl-C (nothing written)",
        141: _CLOSED,
    },
    "compare": {
        0: "compare.png and compare_stages.png written (the second only when the runs logged stage costs)",
        2: "a run folder or its log is unusable, --labels does not match the runs or one is empty, --out is not a "
        "folder or .png, or the PNGs cannot be written",
        130: "interrupted by Ctrl-C (nothing written: the PNGs are written all or none)",
        141: _CLOSED,
    },
    "bench": {
        0: "every measurement ran; results (JSON, PNG, markdown) written",
        2: "a bad option, or the results folder cannot be written",
        130: "interrupted by Ctrl-C (no results are written; results already in the folder stay as they were)",
        141: _CLOSED,
    },
    "schema": {
        0: "printed, or written to --out",
        2: "the --out file cannot be written",
        141: _CLOSED,
    },
}
"""Per subcommand ('' for the top level): exit status -> meaning."""

EXAMPLES: dict[str, list[tuple[str, str]]] = {
    "": [
        ("couplekit validate examples/sand_drop_small.toml", "check a scene; nothing is allocated"),
        ("couplekit run examples/sand_drop_small.toml", "run it: outputs go to runs/sand_drop_small"),
        (
            "couplekit run examples/sand_drop_small.toml --resume runs/sand_drop_small/checkpoint.h5 --frames 40",
            "continue that run to frame 40",
        ),
        ("couplekit sweep examples/sweeps/tiny_substeps.toml", "a parameter sweep on a local Dask cluster"),
        ("couplekit plot runs/sand_drop_small", "draw a run's diagnostics (summary.png)"),
        ("couplekit schema --out scene.schema.json", "the scene JSON Schema, for TOML editors"),
        ("couplekit info --selfcheck", "backend, compilers, GPU; build and check the kernels"),
    ],
    "info": [
        ("couplekit info", "which backend runs, and why"),
        ("couplekit info --selfcheck --backend cpu", "build the host kernels and compare them with NumPy"),
    ],
    "validate": [
        ("couplekit validate examples/fig06_raindrop_small.toml", "valid: a summary, expected Mach, memory"),
        ("couplekit validate my_scene.toml || echo refused", "exit 2 lists every problem with its fix"),
        (
            "couplekit validate examples/fig13_sand_drop_beaker.toml --set fluid.storage=fp16",
            "memory with fp16 storage",
        ),
    ],
    "run": [
        ("couplekit run examples/sand_drop_small.toml", "run time.frames frames into runs/sand_drop_small"),
        ("couplekit run examples/sand_drop_small.toml --frames 5 --out runs/try --overwrite", "a short try"),
        (
            "couplekit run examples/sand_drop_small.toml --resume runs/sand_drop_small/interrupted.h5",
            "continue after Ctrl-C",
        ),
        ("couplekit run examples/fig16_dam_break_sand_small.toml --scheduler subcycle:4", "sand sub-cycled"),
        (
            "couplekit run examples/fig08_sand_densities_small.toml --set fluid.interface_width=8 --set outputs.preview=false",
            "one run with scene keys changed (dotted keys as in sweeps)",
        ),
    ],
    "sweep": [
        ("couplekit sweep examples/sweeps/tiny_substeps.toml", "runs/sweeps/tiny_substeps/results.parquet"),
        ("couplekit sweep examples/sweeps/tiny_substeps.toml --workers 2 --threads 1", "two points at a time"),
        ("couplekit sweep examples/sweeps/tiny_substeps.toml --address 10.0.0.5:8786", "on a cluster"),
    ],
    "plot": [
        ("couplekit plot runs/sand_drop_small", "(re)draw runs/sand_drop_small/summary.png"),
        ("couplekit plot runs/sand_drop_small --out figures/drop.png", "write it elsewhere"),
    ],
    "compare": [
        ("couplekit compare runs/a runs/b --labels lockstep subcycle:8 --out cmp/", "two runs overlaid"),
    ],
    "bench": [
        ("couplekit bench --quick", "Fig. 13's row and five effects, minutes"),
        ("couplekit bench --out results/", "every Table 1 row and effect"),
    ],
    "schema": [
        ("couplekit schema > scene.schema.json", "print it"),
        ("couplekit schema --out docs/scene.schema.json", "regenerate the repository's copy"),
    ],
}
"""Per subcommand ('' for the top level): (command line, what it does)."""

DESCRIPTIONS: dict[str, str] = {
    "": "couplekit: air-water-sand mixtures, a lattice Boltzmann two-phase fluid coupled with MPM sand.\n"
    "Scenes are TOML files in SI units (docs/scene-reference.md); 'couplekit COMMAND --help' tells more.",
    "info": "Version, the backend chosen and why, host compiler, nvcc, CuPy/GPU status and the kernel cache.\n"
    "--selfcheck also builds the self-check kernels and compares them with the NumPy reference.",
    "validate": "Check a scene file; nothing is allocated. Valid: a summary, the fastest expected flow and its\n"
    "lattice Mach number, the memory estimate. Invalid: every problem at once, each naming the dotted key\n"
    "(e.g. bodies[0].geometry.radius) and the fix. What 'run' refuses on this machine only (its memory) is\n"
    "noted, exit 0, so a file validates alike on every host.",
    "run": "Run a scene: a progress bar (frames, steps/s and ETA, without the kernels' compilation), ParaView\n"
    "VTK, PLY and PNG outputs, diagnostics.jsonl and HDF5 checkpoints. --scheduler replaces the scene's\n"
    "[scheduler] table (e.g. subcycle:8); --set KEY=VALUE changes one scene key for the run (validated again,\n"
    "as the file is). Ctrl-C stops between steps and writes interrupted.h5.",
    "sweep": "Run a sweep file (a base scene and a grid of dotted-key values, docs/sweeps.md) on Dask: one row\n"
    "per point in results.parquet. Finished points are kept: the same command resumes an interrupted sweep.",
    "plot": "Draw the diagnostics of a run folder into summary.png: fluid volume drift, lattice speed and Mach,\n"
    "speeds, kinetic energies, sand height and runout, free-surface height, stage costs per frame (a panel\n"
    "only when the run logged its keys; docs/outputs-plots.md). 'run' draws it at the end of every run.",
    "compare": "Overlay the diagnostics of several run folders (a scheduler sweep's points, two commits) in\n"
    "compare.png, and their mean stage costs in compare_stages.png.",
    "bench": "Measure every Table 1 row of paper 000 (its small scene here: s/step, stage costs, memory as\n"
    "allocated) and project s/frame at the paper's size on the paper's RTX PRO 6000, an H100 and an H200; time\n"
    "each effect on and off and check the memory it costs (docs/benchmarks.md).",
    "schema": "Print the JSON Schema of scene files (draft 2020-12), generated from the keys 'validate' checks.\n"
    "TOML editors (Taplo, VS Code's Even Better TOML) then complete and check scene files: associate it\n"
    "with '#:schema path/to/scene.schema.json' on a scene's first line or a .taplo.toml rule\n"
    "(docs/scene-schema.md).",
}
"""Per subcommand ('' for the top level): the text shown under its usage line."""


def epilog(command: str) -> str:
    """The examples and exit codes shown after the options of ``command`` ('' for the top level)."""
    lines = ["examples:"]
    examples = EXAMPLES.get(command, [])
    for line, what in examples:
        lines += [f"  {line}", f"      {what}"]
    lines += ["", "exit codes:"]
    for code, meaning in EXIT_CODES[command].items():
        lines.append(f"  {code:<4} {meaning}")
    return "\n".join(lines if examples else lines[2:])


def add_help_texts(parser: argparse.ArgumentParser, subcommands: argparse._SubParsersAction) -> None:
    """Set the description, examples and exit codes of ``parser`` and of each subcommand in ``subcommands``
    (what ``parser.add_subparsers`` returned), shown as written (RawDescriptionHelpFormatter). A subcommand
    without texts here keeps its own."""
    parser.formatter_class = argparse.RawDescriptionHelpFormatter
    parser.description, parser.epilog = DESCRIPTIONS[""], epilog("")
    for name, sub in subcommands.choices.items():
        if name in DESCRIPTIONS:
            sub.formatter_class = argparse.RawDescriptionHelpFormatter
            sub.description, sub.epilog = DESCRIPTIONS[name], epilog(name)
