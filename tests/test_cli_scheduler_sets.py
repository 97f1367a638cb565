"""`couplekit run --scheduler SPEC --set KEY=VALUE`: the two options change one scene, validated once as a whole.

The bug: --scheduler was applied and validated before the --set values, so multirate:2 with a softer sand set by
--set was refused with the file's P-wave speed, while the same settings given as --set scheduler.* ran.
"""

from __future__ import annotations

import json
from pathlib import Path

from couplekit.cli import main

ROOT = Path(__file__).resolve().parents[1]
FIG17 = str(ROOT / "examples" / "fig17_wet_column_small.toml")
QUIET = ["--set", "outputs.preview=false", "--no-progress"]


def _last_diagnostics(out: Path) -> dict:
    return json.loads((out / "diagnostics.jsonl").read_text().splitlines()[-1])


def test_scheduler_checked_with_the_sand_of_the_set_values(tmp_path, capsys):
    soft = ["--set", "sand.youngs_modulus=3000"]
    # the file's sand (youngs_modulus 56000) does not admit two fluid steps per sand step: refused, key named
    assert (
        main(["run", FIG17, "--frames", "1", "--out", str(tmp_path / "a"), "--scheduler", "multirate:2", *QUIET]) == 2
    )
    err = capsys.readouterr().err
    assert "scheduler.sand_every" in err and "sand.youngs_modulus" in err
    # the softer sand of --set admits it: the pair runs, whichever option comes first on the command line
    out = tmp_path / "b"
    assert main(["run", FIG17, "--frames", "1", "--out", str(out), *soft, "--scheduler", "multirate:2", *QUIET]) == 0
    assert "done: 1 frames" in capsys.readouterr().out
    d = _last_diagnostics(out)
    assert d["frame"] == 1 and 0.4 < d["sand_steps_per_step"] < 0.6  # one sand step per two fluid steps
    # the same run as --set scheduler.* gives the same state
    same = tmp_path / "c"
    sets = ["--set", "scheduler.kind=multirate", "--set", "scheduler.sand_every=2"]
    assert main(["run", FIG17, "--frames", "1", "--out", str(same), *sets, *soft, *QUIET]) == 0
    capsys.readouterr()
    d2 = _last_diagnostics(same)
    assert {k: v for k, v in d.items() if "seconds" not in k and not k.startswith("stage_")} == {
        k: v for k, v in d2.items() if "seconds" not in k and not k.startswith("stage_")
    }


def test_scheduler_made_invalid_by_the_set_values_is_still_refused(tmp_path, capsys):
    # a sand stiffer than 3000 Pa but softer than the file's: multirate:2 breaks its elastic limit again
    argv = ["run", FIG17, "--frames", "1", "--out", str(tmp_path / "a"), "--scheduler", "multirate:2"]
    assert main([*argv, "--set", "sand.youngs_modulus=20000", *QUIET]) == 2
    err = capsys.readouterr().err
    assert "scheduler.sand_every" in err and "sand.youngs_modulus" in err
    assert not (tmp_path / "a").exists()  # refused before the output folder was made
    # a --set scheduler.* key applies on top of --scheduler's table, and is checked with it
    assert main([*argv, "--set", "sand.youngs_modulus=3000", "--set", "scheduler.sand_every=5", *QUIET]) == 2
    err = capsys.readouterr().err
    assert "scheduler.sand_every" in err and "5 x" in err
    # a bad spec or key is still named
    assert main([*argv[:-1], "multirate:x", *QUIET]) == 2
    assert "multirate:x" in capsys.readouterr().err
    assert main([*argv[:-1], "subcycle:auto", "--set", "scheduler.max_substep=8", *QUIET]) == 2
    assert "max_substeps" in capsys.readouterr().err


def test_scheduler_and_set_refused_for_a_resumed_run(tmp_path, capsys):
    for extra in (["--scheduler", "multirate:2"], ["--set", "sand.youngs_modulus=3000"]):
        argv = ["run", FIG17, "--resume", str(tmp_path / "none.h5"), "--out", str(tmp_path / "r"), *extra]
        assert main(argv) == 2
        assert "resumed run" in capsys.readouterr().err
