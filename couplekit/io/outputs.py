"""The output folder of a run: checked before anything is computed, never silently mixed with another run.

:func:`prepare_output` is called by ``couplekit run`` before the solvers are built (and by
:meth:`couplekit.simulation.Simulation.run` for scripts): the folder must be creatable and writable, and one
that holds the outputs of an earlier run (:func:`run_files`) is refused unless the run resumes (a restart
from a checkpoint appends its frames) or ``overwrite`` is given (the earlier run's files are deleted; other
files are left alone).
"""

from __future__ import annotations

from pathlib import Path

__all__ = ["OutputFolderError", "prepare_output", "run_files", "RUN_FILES", "RUN_PATTERNS", "default_output"]

RUN_FILES = (
    "diagnostics.jsonl",
    "checkpoint.h5",
    "interrupted.h5",
    "last_good.h5",
    "diverged.txt",
    "fields.pvd",
    "particles.pvd",
    "summary.png",
    "surface.pvd",
)
"""Files a run writes under fixed names."""

RUN_PATTERNS = (
    "fields_*.vti",
    "particles_*.vtp",
    "particles_*.ply",
    "surface_*.ply",
    "surface_*.obj",
    "surface_*.vtp",
    "preview_*.png",
)
"""The per-frame files a run writes."""


class OutputFolderError(ValueError):
    """The output folder cannot be used (the message names it, what is wrong and the fix)."""


def default_output(scene_name: str) -> Path:
    """``runs/<scene name>``; refused when the name is not a plain folder name (``../x``, ``a/b``), which would
    write outside ``runs/``."""
    name = str(scene_name)
    if not name or name in (".", "..") or Path(name).name != name or "\\" in name:
        raise OutputFolderError(
            f"scene.name {name!r} is not a plain folder name, so runs/<name> would lie elsewhere: give the run a "
            "folder with --out (outputs.directory), or a scene.name without '/', '\\' or '..'"
        )
    return Path("runs") / name


def run_files(out: str | Path) -> list[Path]:
    """The files of an earlier run in ``out`` (fixed names and per-frame files; see the module docstring)."""
    out = Path(out)
    if not out.is_dir():
        return []
    found = [out / n for n in RUN_FILES if (out / n).is_file()]
    for pattern in RUN_PATTERNS:
        found += sorted(p for p in out.glob(pattern) if p.is_file())
    return found


def _describe(files: list[Path]) -> str:
    names = {p.name for p in files}
    frames = sum(1 for p in files if p.name.startswith(("fields_", "particles_")) and p.suffix in (".vti", ".vtp"))
    parts = [n for n in ("checkpoint.h5", "interrupted.h5", "diagnostics.jsonl") if n in names]
    if frames:
        parts.append(f"{frames} frame files")
    return ", ".join(parts) or f"{len(files)} files"


def prepare_output(out: str | Path, *, resume: bool = False, overwrite: bool = False) -> Path:
    """Create and check the output folder ``out`` before a run (module docstring); returns it.

    ``resume``: the run continues from a checkpoint, so an earlier run's files in the folder are its own (new
    frames are appended). ``overwrite``: delete an earlier run's files first. Raises
    :class:`OutputFolderError` when a path component is a file, the folder cannot be created or written, or
    it holds an earlier run's outputs without ``resume`` or ``overwrite``."""
    out = Path(out)
    for parent in reversed(out.parents):
        if parent.exists() and not parent.is_dir():
            raise OutputFolderError(f"output folder {out}: {parent} is a file, not a folder; choose another --out")
    if out.exists() and not out.is_dir():
        raise OutputFolderError(f"output folder {out} is a file; choose another --out (or remove the file)")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputFolderError(
            f"cannot create the output folder {out}: {exc.strerror}; choose another --out"
        ) from None
    probe = out / ".couplekit-write-test"
    try:
        probe.write_text("")
        probe.unlink()
    except OSError as exc:
        raise OutputFolderError(
            f"cannot write into the output folder {out}: {exc.strerror}; choose another --out"
        ) from None
    earlier = run_files(out)
    if earlier and not resume:
        if not overwrite:
            ckpt = next((p for p in earlier if p.name in ("interrupted.h5", "checkpoint.h5")), None)
            resume_hint = f"resume it with --resume {ckpt}, " if ckpt is not None else ""
            raise OutputFolderError(
                f"output folder {out} holds the outputs of an earlier run ({_describe(earlier)}): {resume_hint}"
                "write elsewhere with --out DIR, or replace them with --overwrite"
            )
        for p in earlier:
            p.unlink()
    return out
