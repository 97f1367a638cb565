"""LockstepScheduler (schedulers/lockstep.py): Algorithm 1's stage order, per-stage timing, effects decided
by the solvers given, and the same numbers as calling the stages by hand (one code path)."""

from __future__ import annotations

import time

import numpy as np
import pytest
from couplekit.schedulers.lockstep import COUPLED_STAGES, FLUID_STAGES, SAND_STAGES, LockstepScheduler

from couplekit.backend import BackendUnavailableError, get_backend
from couplekit.coupling import CouplingParams, SandFluidCoupler
from couplekit.fluid.grid import Boundaries
from couplekit.fluid.solver import FluidParams, FluidSolver
from couplekit.sand import SandParams
from couplekit.sand.solver import SandSolver
from couplekit.units import Units

SHAPE = (12, 8, 8)
UNITS = Units(dx=0.005, dt=1e-4)


@pytest.fixture(scope="module")
def cpu1():
    try:
        return get_backend("cpu", threads=1)
    except BackendUnavailableError as exc:  # pragma: no cover - CI has g++
        pytest.skip(f"cpu backend unavailable: {exc}")


def _solvers(be, retention=False, two_phase=True, sand=True, fluid=True):
    g = UNITS.to_lattice(-9.81, "acceleration")
    nz = SHAPE[0]
    phi = (np.arange(nz) < 6).astype(np.float32)[:, None, None] * np.ones(SHAPE, np.float32)
    fl = None
    if fluid:
        fl = FluidSolver(be, SHAPE, FluidParams(rho_l=0.01 if two_phase else 1.0, nu_h=0.1, nu_l=0.1, gravity=(0, 0, g),
                                                eta=2.0 if two_phase else 0.0),
                         boundaries=Boundaries.channel("xyz"), phi=phi if two_phase else None, mixture=sand,
                         external_force=sand)  # fmt: skip
    sd = None
    if sand:
        axes = [np.arange(lo * 2, hi * 2) / 2 + 0.25 for lo, hi in ((3, 5), (3, 5), (6, 8))]
        X, Y, Z = np.meshgrid(*axes, indexing="ij")
        pos = np.stack([X.ravel(), Y.ravel(), Z.ravel()]) * UNITS.dx
        sd = SandSolver(be, SHAPE, UNITS.dx, UNITS.dt, SandParams(density=1500.0, youngs_modulus=1e5),
                        pos, 0.6 * UNITS.dx**3 / 8, gravity=(0, 0, -9.81))  # fmt: skip
    cp = None
    if sand and fluid:
        cp = SandFluidCoupler(sd, fl, UNITS, CouplingParams(retention=retention), moisture=0.05)
    return fl, sd, cp


def _record(obj, names, log, prefix=""):
    for name in names:
        fn = getattr(obj, name)

        def rec(*a, _fn=fn, _n=name, **k):
            log.append(prefix + _n)
            return _fn(*a, **k)

        setattr(obj, name, rec)


def test_coupled_step_runs_algorithm_1_in_order(cpu1):
    """Call order of one coupled step: MPM P2G → fractions → fluid velocity (Σ f c) → source → drag/buoyancy →
    grid update → moisture → G2P → sand velocity → LBM pressure (Eq. 39) → filter (Eq. 40) → controller sums →
    fluid collide/stream → phase-field collide/stream → φ macroscopic → finish."""
    fl, sd, cp = _solvers(cpu1, retention=True)
    log: list[str] = []
    _record(sd, ["p2g", "grid_update", "g2p"], log, "sand.")
    _record(
        cp,
        ["fluid_velocity", "fractions", "phase_source", "exchange", "moisture", "sand_velocity", "finish"],
        log,
        "coupler.",
    )
    _record(fl.ops, ["macro_pressure", "pressure_filter", "collide_stream"], log, "lbm.")
    _record(fl.pf_ops, ["mixture_sums", "collide_stream", "macroscopic"], log, "pf.")
    sched = LockstepScheduler(fl, sd, cp)
    sched.step(1)  # the first step also sets the controller's V0 (one more volume sum)
    log.clear()
    sched.step(1)
    expected = [
        "sand.p2g", "coupler.fractions", "coupler.fluid_velocity", "coupler.phase_source", "coupler.exchange",
        "sand.grid_update", "coupler.moisture", "sand.g2p", "coupler.sand_velocity", "lbm.macro_pressure",
        "lbm.pressure_filter", "lbm.collide_stream", "pf.mixture_sums", "pf.collide_stream", "pf.macroscopic",
        "coupler.finish",
    ]  # fmt: skip
    # the controller's Σ ε φ and Σ ε S: one mixture_sums pass
    dedup = [e for i, e in enumerate(log) if i == 0 or e != log[i - 1]]
    assert dedup == expected, dedup
    times = sched.stage_times()
    assert list(times) == [s for s in sched.stages() if s in times]
    assert set(COUPLED_STAGES) <= set(times)
    assert {"lbm_pressure", "lbm_pressure_filter", "lbm_collide_stream", "phase_field_collide_stream"} <= set(times)
    assert all(v >= 0 for v in times.values())


def test_timing_attributes_time_and_changes_nothing(cpu1):
    """A timed and an untimed scheduler (and the coupler's own step) give bitwise the same state; the stage
    times of a step never exceed its wall time, and time spent inside a stage lands in that stage: a 20 ms
    sleep added to the sand's G2P and to the fluid's pressure filter shows up there (≥ 20 ms) and nowhere
    else (every other stage < 20 ms: on this grid a stage takes well under a millisecond)."""
    runs = []
    for mode in ("timed", "untimed", "coupler"):
        fl, sd, cp = _solvers(cpu1)
        if mode == "coupler":
            cp.step(6)
        else:
            sched = LockstepScheduler(fl, sd, cp, timing=mode == "timed")
            for _ in range(6):
                t0 = time.perf_counter()
                sched.step(1)
                wall = time.perf_counter() - t0
                if mode == "timed":
                    times = sched.stage_times()
                    assert 0 < sum(times.values()) <= wall
                else:
                    assert sched.stage_times() == {}
            if mode == "timed":
                report = sched.cost_report()
                assert abs(sum(r["fraction"] for r in report.values()) - 1) < 1e-9
                sched.detach()
        runs.append((cpu1.to_host(fl.f), cpu1.to_host(fl.h), cpu1.to_host(sd.x), cpu1.to_host(sd.v)))
    for other in runs[1:]:
        for a, b in zip(runs[0], other, strict=True):
            assert np.array_equal(a, b)

    fl, sd, cp = _solvers(cpu1)
    sched = LockstepScheduler(fl, sd, cp)
    sched.step(1)  # first step: kernels loaded
    slow_g2p, slow_filter = sd.g2p, fl.ops._inner.pressure_filter

    def g2p():
        time.sleep(0.02)
        slow_g2p()

    def pressure_filter(*a):
        time.sleep(0.02)
        slow_filter(*a)

    sd.g2p = g2p
    fl.ops._inner.pressure_filter = pressure_filter
    sched.step(1)
    times = sched.stage_times()
    assert times["mpm_g2p"] >= 0.02 and times["lbm_pressure_filter"] >= 0.02, times
    others = {k: v for k, v in times.items() if k not in ("mpm_g2p", "lbm_pressure_filter")}
    assert max(others.values()) < 0.02, others


def test_fluid_only_scene_runs_no_coupling_stage(cpu1):
    fl, _, _ = _solvers(cpu1, sand=False)
    sched = LockstepScheduler(fluid=fl)
    sched.step(2)
    assert set(sched.stage_times()) <= set(FLUID_STAGES)
    assert not sched.effects["coupling"] and fl.fluid_fraction is None and fl.force is None
    ref, _, _ = _solvers(cpu1, sand=False)
    ref.step(2)
    assert np.array_equal(cpu1.to_host(ref.f), cpu1.to_host(fl.f))


def test_sand_only_scene_runs_the_three_mpm_stages(cpu1):
    _, sd, _ = _solvers(cpu1, fluid=False)
    sched = LockstepScheduler(sand=sd)
    sched.step(2)
    assert list(sched.stage_times()) == list(SAND_STAGES)
    _, ref, _ = _solvers(cpu1, fluid=False)
    ref.step(2)
    assert np.array_equal(cpu1.to_host(ref.x), cpu1.to_host(sd.x))


def test_effects_follow_the_scene(cpu1):
    """No retention → no bound-water field; single-phase fluid → no source stage; ablation switch."""
    fl, sd, cp = _solvers(cpu1, retention=False, two_phase=False)
    assert cp.bound is None and cp.moisture_ratio is None
    sched = LockstepScheduler(fl, sd, cp)
    sched.step(1)
    assert "retention_source" not in sched.stage_times() and not sched.effects["source_term"]
    fl, sd, cp = _solvers(cpu1, retention=True)
    sched = LockstepScheduler(fl, sd, cp, source_term=False)
    assert sched.effects["retention"] and not sched.effects["source_term"]
    sched.step(1)
    assert "retention_source" not in sched.stage_times()


def test_refuses_inconsistent_solvers(cpu1):
    fl, sd, cp = _solvers(cpu1)
    with pytest.raises(ValueError, match="SandFluidCoupler"):
        LockstepScheduler(fl, sd)
    fl2, _, _ = _solvers(cpu1, sand=False)
    with pytest.raises(ValueError, match="other solvers"):
        LockstepScheduler(fl2, sd, cp)
    with pytest.raises(ValueError, match="fluid, a sand"):
        LockstepScheduler()
