"""Simulation: wiring of scenes to the solvers, exact restart, NaN/Inf reports, refusals, run outputs."""

from __future__ import annotations

import numpy as np
import pytest
from sim_scenes import run_with_a_nan_after_step_7, tiny_coupled, tiny_fluid, tiny_sand

import couplekit.simulation as simulation
from couplekit.io import read_diagnostics, read_pvd
from couplekit.scene import Scene
from couplekit.simulation import CouplingUnavailableError, InsufficientMemoryError, Simulation


def _sim(d: dict, backend: str = "cpu") -> Simulation:
    return Simulation(Scene.from_dict(d), backend=backend, log=None)


def _same_state(a: Simulation, b: Simulation) -> None:
    sa, sb = a._states(), b._states()
    assert sa.keys() == sb.keys()
    for solver in sa:
        assert sa[solver].keys() == sb[solver].keys()
        for k in sa[solver]:
            x, y = np.asarray(sa[solver][k]), np.asarray(sb[solver][k])
            assert x.dtype == y.dtype and x.shape == y.shape, (solver, k)
            assert x.tobytes() == y.tobytes(), f"{solver}.{k} differs after restart"


@pytest.mark.parametrize("scene", [tiny_sand, tiny_fluid, tiny_coupled], ids=["sand", "fluid", "coupled"])
def test_restart_is_bitwise_on_cpu(tmp_path, scene):
    """A run resumed from a checkpoint is bitwise identical to an uninterrupted one (cpu backend)."""
    straight = _sim(scene())
    straight.step(12)
    first = _sim(scene())
    first.step(5)
    first.save(tmp_path / "c.h5")
    resumed = Simulation.load(tmp_path / "c.h5", backend="cpu", log=None)
    assert resumed.step_count == 5
    resumed.step(7)
    _same_state(straight, resumed)


def test_sand_scene_wiring():
    sim = _sim(tiny_sand())
    p = sim.particles()
    # a 4x4x3-cell block at 2 particles per axis: 8x8x6 particles of grain volume ε0 (dx/2)³, ε0 = 0.6
    # (sand.packing_fraction's default), and mass 1500 kg/m³ × that
    assert p["x"].shape == (3, 384)
    np.testing.assert_allclose(p["volume"].sum(), 0.6 * 0.02 * 0.02 * 0.015, rtol=1e-6)
    np.testing.assert_allclose(p["v"][2], -0.5)
    assert sim.effects["sand"] and sim.effects["obstacles"] and not sim.effects["fluid"]
    sim.step(3)
    d = sim.diagnostics()
    assert d["step"] == 3 and d["time"] == pytest.approx(6e-4)
    np.testing.assert_allclose(d["sand_mass"], 1500 * 0.6 * 0.02 * 0.02 * 0.015, rtol=1e-6)
    assert sim.fields()["sand_fraction"].shape == (12, 12, 12)


def test_heightfield_water_fills_up_to_the_walls():
    """A height-field water body whose x/y range and base lie on the domain boundary starts with no interface
    along the walls and floor, like a box does: only the surface z = h(x, y) carries the tanh profile.
    (Before, its side faces and base on the boundary gave the first cell layer φ ≈ 0.56 at ξ = 8, the corner
    columns emptied in the first frame and drove waves through the pool.)"""
    d = tiny_fluid()
    x = np.linspace(0.0, 0.03, 7)
    h = 0.01 + 0.0025 * np.cos(2 * np.pi * x / 0.03)  # a standing wave: 1 cell of amplitude on a 4-cell layer
    d["bodies"][0]["geometry"] = {
        "type": "heightfield", "heights": [h.tolist()] * 5, "x_range": [0.0, 0.03], "y_range": [0.0, 0.02],
        "base": 0.0,
    }  # fmt: skip
    d["bodies"] = d["bodies"][:1]
    phi = _sim(d).fields()["phi"]  # (z, y, x)
    xc = (np.arange(12) + 0.5) * 0.0025
    k = np.arange(12) + 0.5
    surface = np.interp(xc, x, h) / 0.0025  # cells: the surface is linear between the samples
    slope = np.gradient(np.interp(xc, x, h), xc)
    for i in (0, 6, 11):
        # distance to the local plane of the surface: (k - s) cos(slope); the kinks between segments (0.25 cell
        # per cell of slope change) put it off by < 0.03 in φ
        expect = 0.5 * (1 - np.tanh(2 * (k - surface[i]) / np.sqrt(1 + slope[i] ** 2) / 4))
        np.testing.assert_allclose(phi[:, 0, i], expect, atol=0.03)
        np.testing.assert_allclose(phi[:, 3, i], phi[:, 0, i], atol=1e-6)  # the y walls leave no mark


def test_fluid_scene_wiring():
    sim = _sim(tiny_fluid())
    f = sim.fields()
    assert f["phi"].shape == (12, 8, 12)
    # water layer z < 1 cm (4 cells): φ = ½(1 − tanh(2d/ξ)), d the signed distance in cells, ξ = 4 (after Eq. 48);
    # no interface along the floor and side walls the layer touches
    k = np.arange(12) + 0.5
    d_layer = k - 4
    d_drop = np.sqrt((1.5 - 6) ** 2 + (1.5 - 4) ** 2 + (k - 8) ** 2) - 2  # the drop: centre (6, 4, 8), radius 2 cells
    expect = 0.5 * (1 - np.tanh(2 * np.minimum(d_layer, d_drop) / 4))
    np.testing.assert_allclose(f["phi"][:, 1, 1], expect, rtol=1e-5, atol=1e-6)
    assert f["solid"][0, 4, 8] and not f["solid"][0, 4, 2]
    # the drop moves down at 0.5 m/s, in SI units from fields()
    np.testing.assert_allclose(f["velocity"][2, 8, 4, 6], -0.5, rtol=1e-5)
    eff = sim.effects
    assert eff["phase_field"] and eff["surface_tension"] and eff["volume_controller"] and eff["inflows"]
    assert not eff["sand"] and not eff["drag"]
    sim.step(2)
    d = sim.diagnostics()
    assert {"fluid_volume", "fluid_volume_drift", "mach", "max_speed"} <= d.keys()


def test_single_phase_and_effects_off():
    d = tiny_fluid()
    d["fluid"]["phases"] = 1
    d["bodies"] = [b for b in d["bodies"] if b["kind"] != "water"]
    d["inflows"] = []
    d["domain"]["boundary"] = {}
    sim = _sim(d)
    assert "phi" not in sim.fields() and not sim.effects["phase_field"]
    d = tiny_fluid()
    d["effects"] = {"surface_tension": False, "volume_controller": False}
    eff = _sim(d).effects
    assert not eff["surface_tension"] and not eff["volume_controller"]


def test_coupled_scene_wiring():
    """Sand and fluid together run through SandFluidCoupler (Algorithm 1 order); its fields and the particle
    moisture (retention) are outputs; the fluid gets the mixture inputs."""
    sim = _sim(tiny_coupled())
    eff = sim.effects
    assert eff["coupling"] and eff["drag"] and eff["buoyancy"] and eff["source_term"] and eff["retention"]
    assert sim.fluid.mixture and sim.fluid.external_force
    sim.step(3)
    f, p = sim.fields(), sim.particles()
    assert {"fluid_fraction", "bound_water", "sand_fraction", "phi"} <= f.keys()
    assert "moisture" in p and p["moisture"].shape == p["volume"].shape
    # the sand block (cells x 2..4, y 2..5, z 4..6) shows in the porosity the fluid sees
    assert f["fluid_fraction"][5, 4, 3] < 0.6 and f["fluid_fraction"][10, 4, 10] == 1.0
    assert sim.sand.steps == 3 and sim.fluid.step_count == 3
    d = tiny_coupled(retention=False)
    d["effects"] = {"source_term": False}
    sim = _sim(d)
    assert not sim.effects["source_term"] and not sim.effects["retention"]


@pytest.mark.parametrize(
    ("change", "words"),
    [
        (lambda d: d.update(effects={"drag": False}), "effects.drag"),
        (lambda d: d.update(effects={"buoyancy": False}), "effects.buoyancy"),
    ],
    ids=["drag-off", "buoyancy-off"],
)
def test_what_the_coupler_cannot_do_is_refused(change, words):
    d = tiny_coupled()
    change(d)
    with pytest.raises(CouplingUnavailableError, match="does not do yet") as err:
        _sim(d)
    assert words in str(err.value)


def test_memory_refusal(monkeypatch):
    monkeypatch.setattr(simulation, "available_memory", lambda backend: (1000.0, "test memory"))
    with pytest.raises(InsufficientMemoryError, match="coarser domain.dx"):
        _sim(tiny_sand())


def _variant(d: dict, **changes) -> dict:
    """``d`` with dotted keys set (``"fluid.storage": "fp16"``)."""
    import copy

    d = copy.deepcopy(d)
    for key, value in changes.items():
        *head, last = key.split(".")
        node = d
        for k in head:
            node = node.setdefault(k, {})
        node[last] = value
    return d


@pytest.mark.parametrize(
    "name, data",
    [
        ("fluid", tiny_fluid()),
        ("fluid fp16", _variant(tiny_fluid(), **{"fluid.storage": "fp16"})),
        ("fluid, no surface tension", _variant(tiny_fluid(), **{"effects.surface_tension": False})),
        ("coupled, retention", tiny_coupled()),
        ("coupled", tiny_coupled(retention=False)),
        ("coupled, no source term", _variant(tiny_coupled(retention=False), **{"effects.source_term": False})),
        ("coupled, subcycle", _variant(tiny_coupled(), **{"scheduler.kind": "subcycle", "scheduler.substeps": 2})),
        # m > 1: the exchange velocity gets its own buffer; m = 1 shares the sand velocity's, as lockstep
        ("coupled, multirate", _variant(tiny_coupled(), **{"scheduler.kind": "multirate", "scheduler.sand_every": 2})),
        ("coupled, multirate 1", _variant(tiny_coupled(), **{"scheduler.kind": "multirate", "scheduler.sand_every": 1})),
        ("sand", tiny_sand()),
        # two sand densities: the P2G's volume grid is kept (one density: the node mass over it, SandSolver.node_volume)
        ("coupled, two densities", _variant(tiny_coupled(retention=False), **{"bodies": tiny_coupled()["bodies"] + [
            {"kind": "sand", "density": 900.0,
             "geometry": {"type": "box", "min": [0.012, 0.006, 0.012], "max": [0.016, 0.014, 0.016]}}]})),
    ],
)  # fmt: skip
def test_memory_estimate_matches_the_allocated_arrays(name, data):
    """The estimate `couplekit validate` prints and the memory check uses, against the arrays the solvers hold
    (couplekit.bench.memory, measured from their nbytes): the grid arrays within 1 % (what the estimate leaves
    out: the host's 1-byte fluid mask per cell), the particles an upper bound (bounding boxes x particles per
    cell). The open and periodic faces' index lists, which grow with a face's area, not the volume (~0.2 KB per
    face cell), are left out of both."""
    from couplekit.bench.memory import allocated_arrays

    sc = Scene.from_dict(data)
    est = simulation.memory_estimate(sc)
    sim = Simulation(sc, backend="numpy", log=None, check_memory=False)
    n = tuple(reversed(sc.domain.resolution))
    grids = (n, tuple(s + 2 for s in n))  # interior and padded (z, y, x) shapes
    arrays = allocated_arrays(sim)
    grid_bytes = sum(a.nbytes for a in arrays if a.shape[-3:] in grids)
    n_p = sim.sand.n_particles if sim.sand is not None else 0
    particle_bytes = sum(a.nbytes for a in arrays if n_p and a.shape[-1] == n_p and len(a.shape) <= 2)
    assert est["total"] - est["particles"] == pytest.approx(grid_bytes, rel=0.01)
    assert 0 <= particle_bytes <= est["particles"] + 1e-6 * est["particles"]


def test_nan_is_reported_with_step_field_and_cell(tmp_path):
    sim = _sim(tiny_fluid(frames=3))
    result, report = run_with_a_nan_after_step_7(sim, tmp_path)
    assert result.status == "diverged"
    assert "after step 7" in report and "'pressure'" in report and "(3, 2, 4)" in report
    assert "last good state: step 5" in report
    good = Simulation.load(tmp_path / "last_good.h5", backend="cpu", log=None)
    assert good.step_count == 5
    assert np.isfinite(good.fields()["pressure"]).all()


def test_run_writes_outputs_and_interrupt_resume_is_exact(tmp_path):
    d = tiny_sand(frames=3)
    d["outputs"] = {"preview": True, "preview_every": 3, "checkpoint_every": 1}
    calls = {"n": 0}

    def stop_after_some_steps():
        calls["n"] += 1
        return calls["n"] > 1  # first frame's first chunk runs, then stop

    sim = _sim(d)
    r = sim.run(out=tmp_path, progress=False, stop=stop_after_some_steps)
    assert r.status == "interrupted" and (tmp_path / "interrupted.h5").exists()
    resumed = Simulation.load(tmp_path / "interrupted.h5", backend="cpu", log=None)
    assert resumed.step_count == 5
    r = resumed.run(out=tmp_path, progress=False)
    assert r.status == "done" and r["frames"] == 3
    # the finished run's checkpoint.h5 (step 15) passed interrupted.h5 (step 5): removed, not offered to resume
    assert not (tmp_path / "interrupted.h5").exists() and (tmp_path / "checkpoint.h5").exists()
    straight = _sim(tiny_sand(frames=3))
    straight.step(15)
    _same_state(straight, resumed)
    entries = read_pvd(tmp_path / "particles.pvd")
    assert [e[1] for e in entries] == [f"particles_{i:04d}.vtp" for i in range(4)]
    assert [e[0] for e in entries] == pytest.approx([0.0, 1e-3, 2e-3, 3e-3])
    assert (tmp_path / "particles_0003.ply").exists() and (tmp_path / "fields_0002.vti").exists()
    assert (tmp_path / "preview_0000.png").exists() and (tmp_path / "preview_0003.png").exists()
    assert not (tmp_path / "preview_0001.png").exists()
    recs = read_diagnostics(tmp_path / "diagnostics.jsonl")
    assert [r["frame"] for r in recs] == [0, 1, 2, 3]
    import pyvista as pv

    g = pv.read(tmp_path / "fields_0003.vti")
    np.testing.assert_array_equal(g.point_data["sand_fraction"].reshape(12, 12, 12), straight.fields()["sand_fraction"])


def test_failed_preview_disables_previews_but_not_the_run(tmp_path, monkeypatch):
    import couplekit.io as io

    def broken(*args, **kwargs):
        raise RuntimeError("no EGL display")

    monkeypatch.setattr(io, "render_preview", broken)
    d = tiny_sand(frames=2)
    d["outputs"] = {"preview": True, "preview_every": 1}
    messages = []
    sim = Simulation(Scene.from_dict(d), backend="cpu", log=messages.append)
    r = sim.run(out=tmp_path, progress=False)
    assert r.status == "done"
    warnings = [m for m in messages if "PNG previews disabled" in m]
    assert len(warnings) == 1 and "no EGL display" in warnings[0] and "libegl1" in warnings[0]
    assert (tmp_path / "particles_0002.vtp").exists() and not list(tmp_path.glob("preview_*.png"))


@pytest.mark.parametrize("case", ["substep cap", "particle CFL"])
def test_a_sand_step_limit_mid_run_keeps_the_last_good_state(tmp_path, case, monkeypatch):
    """Sand too fast for its step mid-run is refused before anything goes non-finite: by the sub-cycling
    scheduler's substep cap (SubstepLimitError; the sand made fast by hand, 300 m/s = 2.4 cells per step) or by
    the lockstep's particle-CFL re-check (TimeStepError; its speed reported as 10 km/s, checked every step).
    Simulation.run keeps the run as for a divergence: the last checked state in last_good.h5, the refusal in
    diverged.txt and the result's error, status "diverged"; it used to raise out of run() with nothing saved."""
    capped = case == "substep cap"
    d = tiny_coupled(retention=False)
    d["time"]["frames"] = 3
    if capped:
        d["scheduler"] = {"kind": "subcycle", "substeps": "auto", "max_substeps": 2}
    sim = _sim(d)
    sim.step(3)
    if capped:
        v = sim.backend.to_host(sim.sand.v).copy()
        v[0] = 300.0
        sim.sand.v[...] = sim.backend.asarray(v, v.dtype)
    else:
        sim.sand.cfl_check_every = 1
        monkeypatch.setattr(sim.sand, "_max_speed", lambda: 1e4)
    result = sim.run(out=tmp_path, progress=False, summary=False)
    assert result.status == "diverged", result
    report = (tmp_path / "diverged.txt").read_text()
    assert "stopped at step" in report and "before it could go non-finite" in report
    assert ("max_substeps" in report) if capped else ("particle CFL" in report)
    assert "last good state: step 3" in report and result["error"] in report
    good = Simulation.load(tmp_path / "last_good.h5", backend="cpu", log=None)
    assert good.step_count == 3 and all(np.isfinite(a).all() for a in good.particles().values())


def test_a_stepped_simulation_does_not_append_to_another_runs_folder(tmp_path):
    """run() after step() is a new run: into a folder holding an earlier run of the same scene it is refused
    (it used to take it for a resume and cut that run's diagnostics and .pvd index short); its own earlier run()
    into the same folder it continues."""
    from couplekit.io.outputs import OutputFolderError

    out = tmp_path / "r"
    _sim(tiny_sand()).run(frames=3, out=out, progress=False)
    before = [r["frame"] for r in read_diagnostics(out / "diagnostics.jsonl")]
    sim = _sim(tiny_sand())
    sim.step(sim.steps_per_frame + 1)
    with pytest.raises(OutputFolderError, match="earlier run"):
        sim.run(frames=2, out=out, progress=False)
    assert [r["frame"] for r in read_diagnostics(out / "diagnostics.jsonl")] == before  # nothing cut
    again = tmp_path / "again"
    sim.run(frames=2, out=again, progress=False)
    sim.run(frames=3, out=again, progress=False)  # continues its own run there
    assert [r["frame"] for r in read_diagnostics(again / "diagnostics.jsonl")] == [2, 3]


def test_a_requested_field_the_scene_does_not_make_is_noted(tmp_path):
    """outputs.fields naming a field this scene does not produce (a sand-only scene has no fluid 'solid' field)
    says so when the run starts, instead of writing nothing without a word."""
    lines = []
    d = tiny_sand()
    d.setdefault("outputs", {})["fields"] = ["solid", "sand_fraction"]
    sim = Simulation(Scene.from_dict(d), backend="cpu", log=lines.append)
    sim.run(frames=1, out=tmp_path / "r", progress=False)
    assert any("outputs.fields lists solid" in line and "not written" in line for line in lines)
    assert (tmp_path / "r" / "fields_0001.vti").exists()  # the field it makes is written


def test_a_finished_checkpoint_run_again_says_there_is_nothing_left(tmp_path):
    """A probe (session 23): a finished run's checkpoint run again into a new folder printed a warning that its
    diagnostics.jsonl was empty "because the run stopped before it wrote its first frame"."""
    sim = _sim(tiny_sand(frames=1))
    first = sim.run(out=tmp_path / "a", progress=False)
    assert first.status == "done"
    messages: list[str] = []
    again = Simulation.load(first["checkpoint"], backend="cpu", log=messages.append)
    r = again.run(out=tmp_path / "b", progress=False)
    assert r.status == "done" and r["steps"] == 0
    text = "\n".join(messages)
    assert "nothing left to run: the state is at frame 1 of 1" in text
    assert "empty" not in text and "warning" not in text


def test_a_divergence_logs_the_scenes_cautions_once(tmp_path):
    """A probe (session 25): after a divergence each caution of the scene was logged again by every rebuild of
    the solvers (replaying to the first bad step, keeping the last good state): three times in all."""
    from sim_scenes import run_with_a_nan_after_step_7

    d = tiny_fluid(frames=3)
    d["fluid"].update({"water_lattice_viscosity": 1e-4, "odd_lambda": 0.0})  # the paper's collision: a caution
    lines: list[str] = []
    sim = Simulation(Scene.from_dict(d), backend="cpu", log=lines.append)
    result, _ = run_with_a_nan_after_step_7(sim, tmp_path)
    assert result.status == "diverged"
    cautions = [line for line in lines if line.startswith("caution:")]
    assert cautions and len(cautions) == len(set(cautions)), cautions
