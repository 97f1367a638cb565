"""The README's Python code runs (and docs/units-and-conventions.md's), and every ``couplekit.…`` name the
README mentions imports.

* Every fenced ```` ```python ```` block of README.md is executed, in order, in one namespace, in a temporary
  folder holding a link to the repository's ``examples/`` (the blocks name scene files relative to the
  repository root, as a user in a clone would). A block may be skipped only by the marker comment
  :data:`SKIP_MARKER` on a line of its own; the test reports the skipped blocks, and keeps them rare: none
  is skipped today.
* Every dotted name ``couplekit.a.b.C`` in the README (prose and code alike) resolves: the longest prefix that
  is a module imports, the rest are attributes of it (``couplekit.fluid.FluidSolver``: the module
  ``couplekit.fluid``, its attribute ``FluidSolver``).
"""

from __future__ import annotations

import importlib
import os
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
README = ROOT / "README.md"

SKIP_MARKER = "# readme-test: skip"
"""A line of a ```python block starting with this (e.g. ``# readme-test: skip (runs minutes)``) skips it."""

_BLOCK = re.compile(r"^```python[ \t]*\n(.*?)^```[ \t]*$", re.MULTILINE | re.DOTALL)
_DOTTED = re.compile(r"\bcouplekit(?:\.[A-Za-z_]\w*)+")


def python_blocks(text: str) -> list[str]:
    """The bodies of the fenced ```python blocks of a Markdown ``text``, in order."""
    return [m.group(1) for m in _BLOCK.finditer(text)]


def dotted_names(text: str) -> list[str]:
    """Every distinct ``couplekit.x.y`` name in ``text``, sorted."""
    return sorted(set(_DOTTED.findall(text)))


def resolve(name: str):
    """The object a dotted ``name`` denotes: the longest importable module prefix, then attributes. Raises
    ImportError or AttributeError naming what is missing."""
    parts = name.split(".")
    for k in range(len(parts), 0, -1):
        module_name = ".".join(parts[:k])
        try:
            obj = importlib.import_module(module_name)
        except ModuleNotFoundError as exc:
            missing = exc.name or ""
            if module_name == missing or module_name.startswith(missing + "."):
                continue  # this prefix is not a module: try a shorter one
            raise  # a module of couplekit imports something that is missing: a real error
        for attr in parts[k:]:
            obj = getattr(obj, attr)  # AttributeError names the module and the attribute
        return obj
    raise ImportError(f"no module of {name!r} imports")


def test_the_helpers_find_blocks_names_and_missing_names():
    text = "a `couplekit.fluid.FluidSolver`.\n```python\nx = 1\n```\n```bash\nls\n```\n```python\ny = 2\n```\n"
    assert python_blocks(text) == ["x = 1\n", "y = 2\n"]
    assert dotted_names(text) == ["couplekit.fluid.FluidSolver"]
    assert resolve("couplekit.fluid.solver.FluidSolver") is resolve("couplekit.fluid.FluidSolver")
    with pytest.raises(AttributeError):
        resolve("couplekit.fluid.NoSuchSolver")


def test_readme_names_import():
    names = dotted_names(README.read_text(encoding="utf-8"))
    assert "couplekit.fluid.FluidSolver" in names  # the README names the solvers it says can be driven directly
    missing = []
    for name in names:
        try:
            resolve(name)
        except (ImportError, AttributeError) as exc:
            missing.append(f"{name}: {type(exc).__name__}: {exc}")
    assert not missing, "README names what does not import:\n" + "\n".join(missing)


def run_blocks(doc: Path, folder: Path) -> list[int]:
    """Execute the ```python blocks of ``doc`` in order, in one namespace, in ``folder`` (with a link to the
    repository's ``examples/``); returns the numbers (1-based) of the blocks skipped by :data:`SKIP_MARKER`."""
    blocks = python_blocks(doc.read_text(encoding="utf-8"))
    assert blocks, f"{doc.name} has no ```python block"
    (folder / "examples").symlink_to(ROOT / "examples", target_is_directory=True)
    namespace: dict = {"__name__": "__readme__"}
    skipped = []
    cwd = os.getcwd()
    os.chdir(folder)
    try:
        for i, code in enumerate(blocks, start=1):
            if any(line.strip().startswith(SKIP_MARKER) for line in code.splitlines()):
                skipped.append(i)
                continue
            try:
                exec(compile(code, f"{doc.name} python block {i}", "exec"), namespace)
            except Exception as exc:
                raise AssertionError(f"{doc.name} python block {i} fails: {type(exc).__name__}: {exc}") from exc
    finally:
        os.chdir(cwd)
    assert len(skipped) < len(blocks), f"every {doc.name} python block is skipped: the test would check nothing"
    return skipped


def test_readme_python_blocks_run(tmp_path, capsys):
    skipped = run_blocks(README, tmp_path)
    if skipped:
        with capsys.disabled():
            print(f"\nREADME python blocks skipped by {SKIP_MARKER!r}: {skipped}")


def test_units_doc_python_blocks_run(tmp_path):
    assert not run_blocks(ROOT / "docs" / "units-and-conventions.md", tmp_path)
