"""The output folder of a run: checked before anything is computed, never silently mixed with another run.

:func:`prepare_output` is called by ``couplekit run`` before the solvers are built (and by
:meth:`couplekit.simulation.Simulation.run` for scripts): the folder must be creatable and writable, and one
that holds the outputs of an earlier run (:func:`run_files`) is refused unless the run resumes (a restart
from a checkpoint appends its frames) or ``overwrite`` is given (the earlier run's files are deleted; other
files are left alone).
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

__all__ = [
    "OutputFolderError",
    "OutputIndexError",
    "prepare_output",
    "run_files",
    "RUN_FILES",
    "RUN_PATTERNS",
    "RUN_MARKER",
    "default_output",
    "scene_fingerprint",
    "write_run_marker",
]

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
"""The per-frame files a run writes: the pattern's ``*`` is the frame number, digits only (``surface_0007.obj``;
``surface_scan.obj``, a user's mesh beside the run, is not one)."""

RUN_MARKER = ".couplekit-run.json"
"""Written into the output folder when a run starts: the scene's name and fingerprint, so that a resumed run
can tell its own folder from another run's (:func:`prepare_output`)."""


class OutputFolderError(ValueError):
    """The output folder cannot be used (the message names it, what is wrong and the fix)."""


class OutputIndexError(OutputFolderError, OSError):
    """A ParaView index (.pvd) in the output folder is damaged and cannot be rebuilt from the folder
    (:class:`couplekit.io.vtk.PvdIndex`); the message names the file and the fix. Both an
    :class:`OutputFolderError` (``couplekit run`` prints it and exits 2, as for any unusable folder) and an
    :class:`OSError` (a file that cannot be read back), so either ``except`` catches it."""


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
    found = [out / n for n in RUN_FILES + (RUN_MARKER,) if (out / n).is_file()]
    return found + [p for p, _ in _frame_files(out)]


def _frame_files(out: Path):
    """(path, frame number) of each per-frame file in ``out`` (:data:`RUN_PATTERNS`, the number digits only),
    pattern by pattern, sorted within each."""
    for pattern in RUN_PATTERNS:
        head, _, tail = pattern.partition("*")
        for p in sorted(out.glob(pattern)):
            number = p.name[len(head) : len(p.name) - len(tail)]
            if p.is_file() and number.isdigit():
                yield p, int(number)


def later_frame_files(out: str | Path, frame: int) -> tuple[list[Path], int]:
    """(the per-frame files of frames after ``frame`` in ``out``, the last frame the folder holds: the larger of
    its per-frame files' numbers and the last ``frame`` in its diagnostics log; -1 when neither says)."""
    out = Path(out)
    numbered = list(_frame_files(out))
    later = [p for p, number in numbered if number > frame]
    last = max((number for _, number in numbered), default=-1)
    log = out / "diagnostics.jsonl"
    if log.is_file():
        for line in reversed(log.read_text(encoding="utf-8", errors="replace").splitlines()):
            try:
                rec = json.loads(line)
                last = max(last, int(rec["frame"]))
                break
            except (ValueError, KeyError, TypeError):  # a line cut short by a killed run, or not a record
                continue
    return sorted(later), last


def scene_fingerprint(scene: Mapping[str, Any]) -> str:
    """A short hash of a scene dict (``Scene.to_dict()``): equal for the same scene, run or resumed."""
    text = json.dumps(scene, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def write_run_marker(out: str | Path, scene: Mapping[str, Any]) -> None:
    """Record in ``out`` which scene its run files belong to (:data:`RUN_MARKER`)."""
    name = scene.get("scene", {}).get("name") if isinstance(scene.get("scene"), Mapping) else None
    marker = {"scene": name, "fingerprint": scene_fingerprint(scene)}
    (Path(out) / RUN_MARKER).write_text(json.dumps(marker) + "\n")


def _folder_run(out: Path) -> tuple[str | None, str | None]:
    """(scene name, fingerprint) of the run whose files are in ``out``: from its marker, else from the scene
    stored in its checkpoint (runs written before the marker existed); (None, None) when neither tells."""
    try:
        marker = json.loads((out / RUN_MARKER).read_text())
        return marker.get("scene"), marker.get("fingerprint")
    except (OSError, ValueError, AttributeError):
        pass
    from .checkpoint import CheckpointError, checkpoint_scene

    for name in ("checkpoint.h5", "interrupted.h5", "last_good.h5"):
        path = out / name
        if not path.is_file():
            continue
        try:
            scene = checkpoint_scene(path)
        except CheckpointError:  # a damaged or foreign file: it tells nothing
            continue
        return scene.get("scene", {}).get("name"), scene_fingerprint(scene)
    return None, None


def _describe(files: list[Path]) -> str:
    names = {p.name for p in files}
    frames = sum(1 for p in files if p.name.startswith(("fields_", "particles_")) and p.suffix in (".vti", ".vtp"))
    parts = [n for n in ("checkpoint.h5", "interrupted.h5", "diagnostics.jsonl") if n in names]
    if frames:
        parts.append(f"{frames} frame files")
    return ", ".join(parts) or f"{len(files)} files"


def prepare_output(
    out: str | Path,
    *,
    resume: bool = False,
    overwrite: bool = False,
    scene: Mapping[str, Any] | None = None,
    clear: bool = True,
    frame: int | None = None,
) -> Path:
    """Create and check the output folder ``out`` before a run (module docstring); returns it. A leading ``~``
    is the home folder, as in a shell.

    ``resume``: the run continues from a checkpoint, so an earlier run's files in the folder are its own (new
    frames are appended); with the run's ``scene`` (``Scene.to_dict()``) given, a folder whose files belong to
    another scene is refused (resuming there would mix two runs' frames). ``overwrite``: delete an earlier
    run's files first; with ``clear=False`` only allowed, not done yet (a caller that may still refuse the run
    checks the folder first and lets :meth:`couplekit.simulation.Simulation.run` delete them once the run is
    built: a refused run keeps them). Raises :class:`OutputFolderError` when a path component is a file, the folder cannot be
    created or written, or it holds an earlier run's outputs without ``resume`` or ``overwrite``, or another
    scene's outputs with ``resume``. ``frame``: with ``resume``, the frame the resumed state is at; a folder holding
    later frames of the run (a resume from an earlier checkpoint) is refused unless ``overwrite``, which deletes
    those frames' files (:func:`later_frame_files`; the log is cut back by the run itself)."""
    out = Path(out).expanduser()
    for parent in reversed(out.parents):
        if parent.exists() and not parent.is_dir():
            raise OutputFolderError(
                f"output folder {out}: {parent} is a file, not a folder; choose another --out (run(out=...) in Python)"
            )
    if out.exists() and not out.is_dir():
        raise OutputFolderError(
            f"output folder {out} is a file; choose another --out (run(out=...) in Python; or remove the file)"
        )
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
    if earlier and resume and scene is not None:
        name, fingerprint = _folder_run(out)
        if fingerprint is not None and fingerprint != scene_fingerprint(scene):
            this = scene.get("scene", {}).get("name") if isinstance(scene.get("scene"), Mapping) else None
            raise OutputFolderError(
                f"output folder {out} holds the outputs of another run (scene {name!r}) than the one resumed "
                f"(scene {this!r}): resuming there would mix the two runs' frames; resume into the run's own "
                "folder, or write elsewhere with --out DIR (run(out=...) in Python)"
            )
    if earlier and resume and frame is not None:
        later, last = later_frame_files(out, frame)
        if last > frame and not overwrite:
            raise OutputFolderError(
                f"output folder {out} holds this run's frames up to {last}, beyond frame {frame} of the state "
                f"resumed: resuming there would replace frames {frame + 1}-{last} (their diagnostics, files and the "
                "checkpoints written after them); resume into another folder with --out DIR, or replace them with "
                "--overwrite (in Python: run(out=...), run(overwrite=True))"
            )
        if last > frame and clear:
            for p in later:
                p.unlink()
    if earlier and not resume:
        if not overwrite:
            # the newer of the two: a run resumed from interrupted.h5 and finished leaves it beside a later
            # checkpoint.h5 (a probe: the hint named the stale one)
            saved = [p for p in earlier if p.name in ("interrupted.h5", "checkpoint.h5")]
            ckpt = max(saved, key=lambda p: p.stat().st_mtime_ns) if saved else None
            resume_hint = (
                f"resume it with --resume {ckpt} (Simulation.load({str(ckpt)!r}).run(...) in Python), "
                if ckpt is not None
                else ""
            )
            raise OutputFolderError(
                f"output folder {out} holds the outputs of an earlier run ({_describe(earlier)}): {resume_hint}"
                "write elsewhere with --out DIR, or replace them with --overwrite (in Python: run(out=...), "
                "run(overwrite=True))"
            )
        if clear:
            for p in earlier:
                p.unlink()
    return out
