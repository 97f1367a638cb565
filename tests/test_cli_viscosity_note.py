"""`couplekit validate/run --set time.dt=...` on a file whose fluid viscosities are lattice numbers (Table 1's form,
as every example gives them) changes the physical viscosities, ν = ν_lattice Δx²/Δt: a note says so and gives the
--set values that keep the file's (session 31: a Δt study of Fig. 17's saturation was confounded by a 4× viscosity,
docs/fluid-stability.md)."""

from __future__ import annotations

from pathlib import Path

from couplekit.cli import main

ROOT = Path(__file__).resolve().parents[1]
FIG13 = str(ROOT / "examples" / "fig13_sand_drop_beaker_small.toml")  # dx 6 mm, dt 1.44e-4 s, ν 5e-4 / 1e-2


def _notes(capsys) -> list[str]:
    return [line for line in capsys.readouterr().out.splitlines() if line.startswith("note: ")]


def test_a_halved_time_step_is_noted_with_the_lattice_viscosities_that_keep_the_files(capsys):
    assert main(["validate", FIG13, "--set", "time.dt=7.2e-5"]) == 0
    (note,) = _notes(capsys)
    # water: 5e-4 × 0.006² / 1.44e-4 = 1.25e-4 m²/s in the file, 2.5e-4 at dt / 2
    assert "the water's is 0.00025 m²/s, 2× the file's 0.000125 (the air's likewise)" in note, note
    keep = ["--set", "fluid.water_lattice_viscosity=0.00025", "--set", "fluid.air_lattice_viscosity=0.005"]
    assert " ".join(keep) in note, note
    # following the note: the same physical viscosities, no note
    assert main(["validate", FIG13, "--set", "time.dt=7.2e-5", *keep]) == 0
    assert _notes(capsys) == []


def test_a_coarser_grid_is_noted_too_and_nothing_else_is(tmp_path, capsys):
    # dx 6 mm -> 12 mm (the box is 26 x 26 x 41 cells of 6 mm: 0.156 = 13 x 0.012, 0.246 is not a whole number of
    # 12 mm cells, so the size changes with it)
    sets = ["--set", "domain.dx=0.012", "--set", "domain.size=[0.156, 0.156, 0.24]"]
    assert main(["validate", FIG13, *sets]) == 0
    (note,) = _notes(capsys)
    assert "4× the file's" in note and "dx = 0.012 m" in note, note
    for same in (["--set", "outputs.preview=false"], ["--set", "time.frames=3"], []):
        assert main(["validate", FIG13, *same]) == 0
        assert _notes(capsys) == [], same
    # a file with the viscosities in m²/s keeps them at any dt: no note
    si = tmp_path / "si.toml"
    text = Path(FIG13).read_text()
    text = text.replace("water_lattice_viscosity = 0.0005", "water_viscosity = 0.000125")
    text = text.replace("air_lattice_viscosity = 0.01", "air_viscosity = 0.0025")
    si.write_text(text)
    assert main(["validate", str(si), "--set", "time.dt=7.2e-5"]) == 0
    assert _notes(capsys) == []


def test_run_prints_the_note_before_it_runs(tmp_path, capsys):
    out = tmp_path / "run"
    args = ["run", FIG13, "--frames", "1", "--out", str(out), "--set", "time.dt=1.2e-4", "--no-progress"]
    assert main([*args, "--set", "outputs.preview=false"]) == 0
    text = capsys.readouterr().out
    assert "note: " in text and "the water's is" in text and "done: 1 frames" in text
