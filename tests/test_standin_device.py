"""The cuda backend's Python code on a stand-in device (couplekit/backend/standin.py): CuPy-like arrays that
refuse implicit conversion to NumPy, kernels launched through the device-path host build.  A solver step,
fields(), particles(), diagnostics(), a checkpoint and a restart run there; a missing explicit transfer or a
NumPy call on a device array fails.

The stand-in's results are compared with the cpu-device backend (the same CUDA code paths, driven through
NumPy arrays): both run the same kernels on the same states, so any difference is the cuda Python path's.
That comparison runs on one OpenMP thread (``one_thread`` and cpu-device's ``threads=1``): with more, the scatter kernels' atomic additions land
in a different order every run and cpu-device differs from itself (measured with 2 threads on the coupled scene:
up to 6.5e-6 in sand velocities of 3.9e-3, from nodes of little mass), which says nothing about the path.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent / "scene"))
from sim_scenes import run_with_a_nan_after_step_7, tiny_coupled, tiny_fluid, tiny_jet, tiny_sand  # noqa: E402

from couplekit.backend import Backend, get_backend  # noqa: E402
from couplekit.backend.standin import StandInArray, stand_in_device  # noqa: E402
from couplekit.scene import Scene  # noqa: E402
from couplekit.simulation import Simulation  # noqa: E402

SCENES = {"sand": tiny_sand, "fluid": tiny_fluid, "coupled": tiny_coupled, "jet": tiny_jet}
STEPS = {"jet": 70}  # the jet's first particle layer is emitted after ~60 steps; 3 steps elsewhere


@pytest.fixture
def gpu(cpu_backend):
    """The cuda backend on the stand-in device (skips without a host compiler)."""
    with stand_in_device():
        yield get_backend("cuda")


@pytest.fixture
def one_thread():
    """OpenMP regions started from this thread run on one thread for the test (the calling thread's
    nthreads-var, shared by every kernel library loaded in the process through libgomp), then as before."""
    gomp = ctypes.CDLL(ctypes.util.find_library("gomp") or "libgomp.so.1")
    before = gomp.omp_get_max_threads()
    gomp.omp_set_num_threads(1)
    yield
    gomp.omp_set_num_threads(before)


def _sim(name: str, backend) -> Simulation:
    return Simulation(Scene.from_dict(SCENES[name]()), backend=backend, log=None)


# ------------------------------------------------------------------------------------------ the arrays
def test_arrays_refuse_implicit_conversion_and_numpy_calls(gpu):
    xp = gpu.xp
    a = xp.zeros((3, 4), dtype=np.float32)
    assert isinstance(a, StandInArray) and xp.ndarray is StandInArray
    for refused in (
        lambda: np.asarray(a),  # implicit device -> host copy
        lambda: np.array(a),
        lambda: np.sum(a),  # a NumPy function on a device array
        lambda: np.isfinite(a),  # a NumPy ufunc
        lambda: a + np.ones((3, 4), np.float32),  # a host array mixed in
        lambda: xp.maximum(a, np.ones((3, 4), np.float32)),
    ):
        with pytest.raises(TypeError):
            refused()
    with pytest.raises(AttributeError):
        a.ctypes  # noqa: B018 - NumPy-only attribute
    assert not hasattr(a.flags, "writeable")  # as CuPy's flags


def test_arrays_allow_explicit_transfers_and_device_math(gpu):
    xp = gpu.xp
    host = np.arange(12, dtype=np.float32).reshape(3, 4)
    a = gpu.asarray(host)
    b = np.float32(2) * a + 1  # a NumPy scalar on the left is fine, as on CuPy
    s = b.sum()
    assert isinstance(s, StandInArray) and s.shape == ()  # reductions stay on the device
    assert float(s) == float((2 * host + 1).sum())
    assert isinstance(gpu.to_host(b), np.ndarray)
    np.testing.assert_array_equal(xp.asnumpy(b[1:, ::2]), (2 * host + 1)[1:, ::2])
    a[0] = gpu.asarray(np.ones(4, np.float32))
    a[1] = np.float32(5)  # a scalar fill
    assert a.get()[:2].tolist() == [[1, 1, 1, 1], [5, 5, 5, 5]]
    with pytest.raises(ValueError, match="non-scalar numpy.ndarray"):
        a[...] = host  # CuPy refuses a host array as the value of an assignment
    a.set(host)  # the explicit host -> device copy
    np.testing.assert_array_equal(a.get(), host)


def test_kernels_take_device_arrays_and_numpy_scalars_only(gpu):
    fn = gpu.module("selfcheck.cu").function("scatter_add")
    idx = gpu.asarray(np.array([0, 1, 1, 3], np.int32))
    val = gpu.asarray(np.array([1, 2, 3, 4], np.float32))
    out = gpu.xp.zeros(4, dtype=np.float32)
    fn(4, idx, val, out, 0.5)  # the cuda backend casts the Python float to float32 before the launch
    assert out.get().tolist() == [0.5, 2.5, 0.0, 2.0]
    kernel = fn._kernel  # the raw launch refuses what CuPy would marshal wrongly
    with pytest.raises(TypeError, match="Python float"):
        kernel((1,), (256,), (np.int64(4), idx, val, out, 0.5))
    with pytest.raises(TypeError, match="host numpy.ndarray"):
        kernel((1,), (256,), (np.int64(4), idx, val, np.zeros(4, np.float32), np.float32(0.5)))
    with pytest.raises(ValueError, match="1024"):
        kernel((1,), (2048,), (np.int64(4), idx, val, out, np.float32(0.5)))


def test_selfcheck_kernels_pass(gpu):
    from couplekit.selfcheck import run_selfcheck

    results = run_selfcheck(gpu)
    assert results and all(r.ok for r in results), [(r.name, r.error) for r in results]


def test_the_real_module_is_put_back(cpu_backend):
    before = sys.modules.get("cupy")
    with stand_in_device() as fake:
        import cupy

        assert cupy is fake
    assert sys.modules.get("cupy") is before


# ------------------------------------------------------------------------------------------ Simulation
def _host_dict(d: dict) -> dict:
    for k, v in d.items():
        assert isinstance(v, np.ndarray), f"{k} is a {type(v).__name__}, not a host NumPy array"
    return d


@pytest.mark.parametrize("name", list(SCENES))
def test_simulation_steps_reports_and_restarts_on_the_stand_in(gpu, tmp_path, name, one_thread):
    sim = _sim(name, gpu)
    assert sim.backend.name == "cuda"
    solver = sim.fluid if sim.fluid is not None else sim.sand
    assert any(isinstance(v, StandInArray) for v in vars(solver).values())  # the state lives on the "device"
    steps = STEPS.get(name, 3)
    n0 = sim.sand.x.shape[1] if sim.sand is not None else 0
    sim.step(steps)
    fields, parts, diag = _host_dict(sim.fields()), _host_dict(sim.particles()), sim.diagnostics()
    assert fields and all(type(v) is float for v in diag.values()) and diag["step"] == steps
    assert bool(parts) == (name != "fluid")
    if name == "jet":
        assert parts["x"].shape[1] > n0  # the jet emitted particles on the device

    # the same kernels driven through NumPy arrays (cpu-device) give the same state
    ref = _sim(name, get_backend("cpu-device", threads=1))
    ref.step(steps)
    for k, v in ref.fields().items():
        np.testing.assert_allclose(fields[k], v, rtol=1e-5, atol=1e-6 * max(1.0, float(np.abs(v).max())), err_msg=k)
    for k, v in ref.particles().items():
        np.testing.assert_allclose(parts[k], v, rtol=1e-5, atol=1e-7, err_msg=k)

    # a checkpoint, a restart on the stand-in, and the restarted run continues like the original
    sim.save(tmp_path / "c.h5")
    resumed = Simulation.load(tmp_path / "c.h5", backend=gpu, log=None)
    assert resumed.step_count == steps
    resumed.step(2)
    sim.step(2)
    for k, v in sim.fields().items():
        np.testing.assert_allclose(resumed.fields()[k], v, rtol=1e-5, atol=1e-6 * max(1.0, float(np.abs(v).max())))
    assert resumed.diagnostics()["step"] == steps + 2


def test_a_missing_transfer_fails(gpu, tmp_path, monkeypatch):
    sim = _sim("coupled", gpu)
    sim.step(1)
    with pytest.raises(TypeError, match="NumPy"):
        np.max(sim.sand.x)  # a NumPy call on a device array
    with pytest.raises(TypeError, match="[Ii]mplicit conversion"):
        np.asarray(sim.sand.x)
    # without its device -> host copy, what fields() returns cannot be written, nor can a checkpoint
    monkeypatch.setattr(Backend, "to_host", lambda self, a: a)
    with pytest.raises(TypeError, match="[Ii]mplicit conversion"):
        sim.save(tmp_path / "c.h5")
    with pytest.raises(TypeError, match="[Ii]mplicit conversion"):
        np.savez(tmp_path / "f.npz", **sim.fields())


def test_a_nan_on_the_device_is_reported_and_the_last_good_state_kept(gpu, tmp_path):
    """The divergence path of run() (finite checks, the last good checkpoint, the replay to the first bad
    step) on device arrays."""
    sim = Simulation(Scene.from_dict(tiny_fluid(frames=3)), backend=gpu, log=None)
    result, report = run_with_a_nan_after_step_7(sim, tmp_path)
    assert result.status == "diverged"
    assert "after step 7" in report and "'pressure'" in report and "(3, 2, 4)" in report
    good = Simulation.load(tmp_path / "last_good.h5", backend=gpu, log=None)
    assert good.step_count == 5 and np.isfinite(good.fields()["pressure"]).all()
