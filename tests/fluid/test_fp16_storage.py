"""fp16 storage of the populations f and h (``storage="fp16"``, couplekit.fluid.storage): the encoding, the
kernel signatures, every kernel that touches f or h against the NumPy reference with the same storage, the
overflow to inf that the divergence check sees, and the checkpoint's refusal of another storage.

Tolerances of the kernel-vs-reference comparisons: both start from the same binary16 values (decoded exactly),
compute (float32 in the kernels, float64 in the reference) and round the result to binary16, nearest even. The
arithmetic differs by the float32 round-off of the fp32 tests (``ATOL`` = 2e-6 absolute, their docstrings), so
a stored value may differ by that plus one binary16 ulp where the two results fall on either side of a rounding
boundary: |kernel − reference| ≤ ATOL + ulp16(value) / scale, and most values must agree bit for bit (a wrong
scale, shift or slot would differ by far more than one ulp everywhere).
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

import numpy as np
import pytest
from fluid_states import BOUNDARY_SETS, chem_of, random_state

from couplekit.backend import KernelArgumentError, get_backend
from couplekit.backend.signature import parse_kernels
from couplekit.fluid import FluidParams, FluidSolver, KernelOps, ReferenceOps, from_stored, to_stored
from couplekit.fluid import storage as st
from couplekit.fluid.phasefield import PhaseFieldKernelOps, PhaseFieldReferenceOps
from couplekit.lattice import C27, W7

ROOT = Path(__file__).parents[2]
ATOL = 2e-6
EFFECTS = {
    "single": {},
    "all": {"two_phase": True, "surface_tension": True, "mixture": True, "external_force": True},
}
PARAMS = (1.0, 0.00125, 0.01, 0.05)  # rho_h, rho_l, nu_h, nu_l (as tests/fluid/test_lbm_kernels.py)
GRAVITY = (1e-5, -2e-5, 3e-5)


@pytest.fixture(scope="module")
def cpu(kernel_backend):
    """cpu and cpu-device in turn: the host and the CUDA code paths (the CUDA conversion is PTX; the device-path
    build runs the host's _Float16 one, which rounds alike)."""
    return kernel_backend


def _fp16_state(seed, boundaries, shape=None):
    s = random_state(seed, boundaries, **({"shape": shape} if shape else {}))
    s["f"] = to_stored(from_stored(s["f"]), "fp16")
    return s, {k: (v.copy() if isinstance(v, np.ndarray) else v) for k, v in s.items()}


def assert_stored_close(k, r, scale, mask=None, min_equal=0.9, extra=None):
    """Stored binary16 arrays within ATOL + one ulp (module docstring) plus ``extra`` (scaled, per value), most
    bitwise equal."""
    assert k.dtype == r.dtype == np.float16
    extra = np.zeros(k.shape) if extra is None else extra
    if mask is not None:
        k, r, extra = k[..., mask], r[..., mask], extra[..., mask]
    k64, r64 = k.astype(np.float64), r.astype(np.float64)
    ulp = np.spacing(np.maximum(np.abs(k), np.abs(r))).astype(np.float64)
    excess = np.abs(k64 - r64) - (ATOL * scale + ulp + extra)
    assert excess.max() <= 0, f"worst excess {excess.max() / scale:.3g} beyond ATOL + 1 ulp"
    assert np.isfinite(k64).all()
    assert np.mean(k64 == r64) >= min_equal, f"only {np.mean(k64 == r64):.3f} bitwise equal"


# ---------------------------------------------------------------------------------------------- encoding
def test_constants_match_the_kernel_header():
    """couplekit.fluid.storage mirrors kernels/common.cuh's fp16 branch (the first definitions there)."""
    text = (ROOT / "kernels" / "common.cuh").read_text()
    for name, value in (("CK_F_SCALE", st.F_SCALE), ("CK_H_SCALE", st.H_SCALE), ("CK_H_REST", st.H_REST)):
        m = re.search(rf"#define {name} ([0-9.]+)", text)
        assert m and float(m.group(1)) == value, name


def test_encoding_rounds_to_nearest_even_and_overflows_to_inf():
    rng = np.random.default_rng(0)
    shifted = rng.uniform(-0.3, 0.3, (27, 4, 4, 4)) * 10.0 ** rng.uniform(-8, 0, (27, 4, 4, 4))
    w = st.weights27(4)
    f = to_stored(shifted + w, "fp16")
    assert f.dtype == np.float16
    back = from_stored(f) - w
    # one rounding of (f - w) * 32768: relative 2^-11 in the normal range, absolute 2^-25 / 32768 below it
    assert np.all(np.abs(back - shifted) <= np.maximum(2.0**-11 * np.abs(shifted), 2.0**-25 / st.F_SCALE))
    assert np.array_equal(to_stored(from_stored(f), "fp16"), f)  # decoding is exact: a round trip is the identity
    # round to nearest even, as numpy (and the kernels): 1 + 2^-11 is a tie between 1 and 1 + 2^-10
    tie = np.full((27, 1), (1.0 + 2.0**-11) / st.F_SCALE)
    assert st.encode_f(tie, "fp16")[0, 0] == np.float16(1.0)
    # 65504 / 32768 is the largest stored |f - w|; beyond it the value becomes inf, not a clamp
    big = np.full((27, 1), 2.5)
    assert np.isinf(st.encode_f(big, "fp16")).all()
    h = st.encode_h(np.full((7, 1), 3.0), "fp16")
    assert np.isinf(h).all()
    # h: resting water (h = w) and air (h = 0) are stored exactly
    assert np.array_equal(st.decode_h(st.encode_h(W7.reshape(7, 1), "fp16")), W7.reshape(7, 1))
    assert np.all(st.decode_h(st.encode_h(np.zeros((7, 1)), "fp16")) == 0)


@pytest.mark.parametrize("kernel", ["lbm_store_convert", "lbm_store_convert_scalar"])
def test_kernel_conversions_match_numpy_on_every_binary16(cpu, kernel):
    """lbm_store_convert (CK_STORE / CK_LOAD at scale 1; ``_scalar``: CK_STORE_SCALAR / CK_LOAD_SCALAR, F16C on the
    host): every one of the 65536 binary16 values decodes as
    NumPy's float16 does (NaNs: NaN), and float32 values on both sides of every rounding boundary (the exact
    midpoints between neighbouring binary16 values and their float32 neighbours, subnormal, normal and beyond
    65504) encode as NumPy's round to nearest even, overflow to inf included."""
    fn = cpu.module("lbm_halo.cu", {"CK_STORAGE_FP16": 1}).function(kernel)
    bits = np.arange(65536, dtype=np.uint32).astype(np.uint16)
    halves = bits.view(np.float16)
    finite = np.isfinite(halves)
    vals = halves[finite].astype(np.float32)
    out, back = np.zeros(vals.size, np.float16), np.zeros(vals.size, np.float32)
    fn(vals.size, vals, out, back)
    assert np.array_equal(out.view(np.uint16), halves[finite].view(np.uint16))  # exact values round-trip
    assert np.array_equal(back, vals)
    # midpoints between consecutive positive binary16 values, and their float32 neighbours
    pos = np.sort(np.unique(np.abs(halves[finite].astype(np.float64))))
    mid = (pos[:-1] + pos[1:]) / 2
    mid = np.concatenate([mid, [65520.0, 70000.0, 1e30]])  # 65520 rounds to inf (ties to even), beyond too
    m32 = mid.astype(np.float32)
    probe = np.concatenate([m32, np.nextafter(m32, 0), np.nextafter(m32, np.inf)]).astype(np.float32)
    probe = np.concatenate([probe, -probe, np.array([np.inf, -np.inf, np.nan], np.float32)])
    out, back = np.zeros(probe.size, np.float16), np.zeros(probe.size, np.float32)
    fn(probe.size, probe, out, back)
    with np.errstate(over="ignore"):
        want = probe.astype(np.float16)
    nan = np.isnan(probe)
    assert np.array_equal(out[~nan].view(np.uint16), want[~nan].view(np.uint16))
    assert np.isnan(out[nan]).all() and np.isnan(back[nan]).all()
    assert np.array_equal(back[~nan], want[~nan].astype(np.float32))


def test_storage_choices_are_checked():
    with pytest.raises(ValueError, match="'fp32', 'fp16'"):
        st.check_storage("bf16")
    with pytest.raises(ValueError, match="FluidSolver storage"):
        FluidSolver(get_backend("numpy"), (4, 4, 4), FluidParams(), storage="fp64")


def test_signature_resolves_the_store_type_with_the_defines():
    src = "KERNEL void k(const long long n, ck_store_t* RESTRICT f, const unsigned short* b) {}"
    (p32,) = parse_kernels(src).values()
    (p16,) = parse_kernels(src, defines={"CK_STORAGE_FP16": 1}).values()
    assert p32.params[1].dtype == np.float32 and p16.params[1].dtype == np.float16
    assert p16.params[2].dtype == np.uint16
    assert "ck_store_t" in p16.describe() and "float16" in p16.describe()
    with pytest.raises(ValueError, match="must be a pointer"):
        parse_kernels("KERNEL void k(const long long n, ck_store_t f) {}")


def test_an_fp16_module_refuses_float32_populations(cpu):
    ko = KernelOps(cpu, storage="fp16")
    s = random_state(3, BOUNDARY_SETS["periodic"])  # float32 f
    with pytest.raises(KernelArgumentError, match="float16"):
        ko.collide_stream(
            s["f"], s["flags"], s["velocity"], None, None, None, s["pbar"], 0, *PARAMS, *GRAVITY
        )  # fmt: skip


# ---------------------------------------------------------------------------------------------- flow kernels
@pytest.mark.parametrize("effects", list(EFFECTS))
@pytest.mark.parametrize("boundaries", list(BOUNDARY_SETS))
@pytest.mark.parametrize("parity", [0, 1])
@pytest.mark.parametrize("shape", [None, (4, 5, 21)], ids=["default", "21-cell rows"])
def test_collide_stream_matches_reference_fp16(cpu, effects, boundaries, parity, shape):
    """21-cell rows: the host loop's last 5 cells run as one more vector whose first 11 lanes keep their stored
    binary16 bits (kernels/lbm_core.cuh lbm_row_tail)."""
    ko = KernelOps(cpu, **EFFECTS[effects], storage="fp16")
    ro = ReferenceOps(**EFFECTS[effects], storage="fp16")
    sk, sr = _fp16_state(11 + parity, BOUNDARY_SETS[boundaries], shape)
    f0 = sk["f"].copy()
    for ops, s in ((ko, sk), (ro, sr)):
        ops.collide_stream(
            s["f"], s["flags"], s["velocity"], s["phi"], s["eps"], s["force"], s["pbar"], parity,
            *PARAMS, *GRAVITY, chemical_potential=chem_of(ops, s),
        )  # fmt: skip
    state = (sk["flags"] == 0) | (sk["flags"] == 3)
    # a cell with wall links reads the parked (rounded) bounced values: its velocity and its 27 outputs (pushed
    # to x + c_j) may differ by their ulps, times 2 for the collision's mixing of the populations
    parked = _wall_link_rounding({**sk, "f": f0}, parity).sum(axis=0)
    extra = _wall_link_rounding(sk, parity)
    flat_parked, flat_extra = parked.reshape(-1), extra.reshape(27, -1)
    px, pxy = sk["flags"].shape[2], sk["flags"].shape[2] * sk["flags"].shape[1]
    for j in range(27):
        off = int(C27[j] @ np.array([1, px, pxy]))
        flat_extra[j] += 2.0 * np.roll(flat_parked, off)  # what the writer cell x = target - c_j read
    assert_stored_close(sk["f"], sr["f"], st.F_SCALE, state, extra=extra)
    assert np.all(np.abs(sk["velocity"] - sr["velocity"]) <= ATOL + parked[None] / st.F_SCALE)
    assert np.abs(from_stored(sk["f"]) - from_stored(f0)).max() > 1e-3  # the step changed the state


def _wall_link_rounding(s, parity):
    """Scaled allowance at the bounce-back slots of an odd step: the kernels park the bounced value in the wall
    cell (lbm_wall_prefill) and move the pushed one back (lbm_wall_bounce), each a stored value, so a wall link's
    population is rounded twice more than in the reference, on intermediates that differ from it by the moving
    wall's 6 w_j c_j.u_w (measured up to 69 ulps of a small final value: its ulp is much finer than theirs).
    Allowed: one ulp of each intermediate, |value| + |6 w_j c_j.u_w| bounding it, times 2."""
    from couplekit.fluid.grid import wall_links
    from couplekit.lattice import W27

    extra = np.zeros(s["f"].shape)
    if not parity & 1:
        return extra
    cell, d = wall_links(s["flags"])
    px, pxy = s["flags"].shape[2], s["flags"].shape[2] * s["flags"].shape[1]
    v = s["velocity"].reshape(3, -1).astype(np.float64)
    off = C27[d] @ np.array([1, px, pxy])
    term = 6.0 * W27[d] * np.abs((C27[d].T * v[:, cell - off]).sum(axis=0)) * st.F_SCALE
    value = np.abs(s["f"].reshape(27, -1)[d, cell].astype(np.float64))
    flat = extra.reshape(27, -1)
    flat[d, cell] = 2.0 * np.spacing((value + term).astype(np.float16)).astype(np.float64)
    return extra


@pytest.mark.parametrize("boundaries", list(BOUNDARY_SETS))
@pytest.mark.parametrize("parity", [0, 1])
def test_pressure_and_momentum_read_fp16_populations(cpu, boundaries, parity):
    """Same decoded inputs, so the fp32 tests' tolerances hold (tests/fluid/test_lbm_kernels.py)."""
    eff = EFFECTS["all"]
    ko, ro = KernelOps(cpu, **eff, storage="fp16"), ReferenceOps(**eff, storage="fp16")
    sk, sr = _fp16_state(21 + parity, BOUNDARY_SETS[boundaries])
    p0, f0 = sk["p"].copy(), sk["f"].copy()
    out = {}
    for name, ops, s in (("k", ko, sk), ("r", ro, sr)):
        ops.macro_pressure(
            s["f"], s["flags"], s["velocity"], s["phi"], s["eps"], s["sand_v"], s["slip"], s["p"], parity, *PARAMS[:2]
        )  # fmt: skip
        out[name] = np.zeros_like(s["velocity"])
        ops.momentum(s["f"], s["flags"], s["velocity"], out[name], parity)
    # odd steps with walls: the sums read the parked bounced values, rounded once more (_wall_link_rounding)
    parked = _wall_link_rounding({**sk, "f": f0}, parity).sum(axis=0) / st.F_SCALE
    assert np.all(np.abs(sk["p"] - sr["p"]) <= 5e-7 + parked / 3.0)  # cs² ρ Σ, ρ ≤ 1
    assert np.all(np.abs(out["k"] - out["r"]) <= 1e-6 + parked[None])
    assert np.abs(sk["p"] - p0).max() > 1e-5 and np.abs(out["r"]).max() > 1e-2


@pytest.mark.parametrize("boundaries", list(BOUNDARY_SETS))
def test_halo_fold_outflow_copies_of_fp16_populations_are_exact(cpu, boundaries):
    ko, ro = KernelOps(cpu, storage="fp16"), ReferenceOps(storage="fp16")
    sk, sr = _fp16_state(31, BOUNDARY_SETS[boundaries])
    for ops, s in ((ko, sk), (ro, sr)):
        ops.halo_pull(s["f"], s["ghost"], s["image"], s["links"])
        ops.halo_copy(s["p"], s["ghost"], s["image"])  # a float32 field through the same ops
        ops.fold(s["f"], s["ghost"], s["image"], s["links"])
    for key in ("f", "p"):  # the outflow ghosts (arithmetic where backflow is taken out): test_outflow_backflow.py
        np.testing.assert_array_equal(sk[key], sr[key])


# ---------------------------------------------------------------------------------------------- phase field
sys.path.insert(0, str(Path(__file__).parent))
from test_phasefield_kernels import PERIODIC_CASES, SHAPE  # noqa: E402
from test_phasefield_kernels import random_state as pf_random_state  # noqa: E402


def _pf_state(seed, periodic, **kw):
    s = pf_random_state(seed, periodic, **kw)
    s["h"] = st.encode_h(s["h"], "fp16")
    return s


@pytest.mark.parametrize("periodic", PERIODIC_CASES)
@pytest.mark.parametrize("parity", [0, 1])
def test_phase_collide_stream_matches_reference_fp16(cpu, periodic, parity):
    s = _pf_state(10 + parity, periodic)
    kernel = PhaseFieldKernelOps(cpu, periodic, storage="fp16")
    ref = PhaseFieldReferenceOps(periodic, storage="fp16")
    h_k, h_r = s["h"].copy(), s["h"].copy()
    args = (s["phi"], s["u"], s["source"], s["flags"], parity, 0.04, 4.5, 0.6)
    kernel.collide_stream(h_k, *args)
    ref.collide_stream(h_r, *args)
    # the rest population is the exact balance of the six rounded moving ones (kernels/phasefield.cu
    # pf_relax), a few float32 roundings of the cell's phi (<= 1.4) more than the fp32 test's: 4 ATOL
    k64, r64 = st.decode_h(h_k), st.decode_h(h_r)
    ulp = np.spacing(np.maximum(np.abs(h_k), np.abs(h_r))).astype(np.float64) / st.H_SCALE
    assert (np.abs(k64 - r64) - (4 * ATOL + ulp)).max() <= 0
    assert np.mean(h_k == h_r) >= 0.9
    assert np.abs(k64 - st.decode_h(s["h"])).max() > 1e-2


@pytest.mark.parametrize("periodic", PERIODIC_CASES[:2])
@pytest.mark.parametrize("parity", [0, 1])
def test_phase_set_equilibrium_and_macroscopic_fp16(cpu, periodic, parity):
    s = _pf_state(30 + parity, periodic, boundary_kinds=(2, 3, 1))
    kernel = PhaseFieldKernelOps(cpu, periodic, storage="fp16")
    ref = PhaseFieldReferenceOps(periodic, storage="fp16")
    from couplekit.fluid.phasefield import padded_shape

    h_k = np.zeros((7, *padded_shape(SHAPE)), dtype=np.float16)
    h_r = h_k.copy()
    kernel.set_equilibrium(h_k, s["phi"], s["u"], s["flags"], parity)
    ref.set_equilibrium(h_r, s["phi"], s["u"], s["flags"], parity)
    assert_stored_close(h_k, h_r, st.H_SCALE, min_equal=0.95)
    phi_k, phi_r = (np.where(s["flags"] == 2, s["phi"], -9.0).astype(np.float32) for _ in range(2))
    kernel.macroscopic(s["h"], phi_k, s["u"], s["flags"], parity)
    ref.macroscopic(s["h"], phi_r, s["u"], s["flags"], parity)
    np.testing.assert_allclose(phi_k, phi_r, rtol=0, atol=ATOL)


# ---------------------------------------------------------------------------------------------- solver
@pytest.mark.parametrize("backend", ["cpu", "numpy"])
def test_a_two_phase_solver_runs_fp16_and_stays_near_fp32(backend):
    """A 10³ drop with random 1e-2 velocities, 6 steps: fp16 storage allocates float16 f and h, and its velocity
    stays within 2e-5 of fp32's (measured 3.2e-6 on cpu: a few stored roundings of 2^-11 of values ≲ 0.01)."""
    shape = (10, 10, 10)
    z, y, x = np.meshgrid(*[np.arange(n) for n in shape], indexing="ij")
    r = np.sqrt((x - 4.5) ** 2 + (y - 4.5) ** 2 + (z - 4.5) ** 2)
    phi = 0.5 * (1 - np.tanh(2 * (r - 3) / 4))
    u = 0.01 * np.random.default_rng(0).standard_normal((3, *shape))
    prm = FluidParams(rho_l=0.1, nu_h=0.05, nu_l=0.05, sigma=1e-3)
    out = {}
    for storage in ("fp32", "fp16"):
        s = FluidSolver(get_backend(backend), shape, prm, phi=phi, velocity=u, storage=storage)
        assert s.f.dtype == s.h.dtype == st.dtype_of(storage)
        s.step(6)
        out[storage] = s.fields()
    assert np.abs(out["fp16"]["velocity"] - out["fp32"]["velocity"]).max() < 2e-5
    assert np.abs(out["fp16"]["phi"] - out["fp32"]["phi"]).max() < 2e-3


def _tiny_fluid_fp16() -> dict:
    sys.path.insert(0, str(ROOT / "tests" / "scene"))
    from sim_scenes import tiny_fluid

    d = tiny_fluid()
    d["fluid"]["storage"] = "fp16"
    return d


def test_an_out_of_range_population_becomes_inf_and_the_divergence_check_names_it():
    """One cell's stored f - w along +x set to the largest binary16 value (65504 / 32768 ≈ 2, finite): its
    collision gives populations beyond the range, which are stored as inf (not clamped), and
    Simulation.check_finite stops the run naming the fluid."""
    from couplekit.scene import Scene
    from couplekit.simulation import Simulation, SimulationDiverged

    sim = Simulation(Scene.from_dict(_tiny_fluid_fp16()), backend="cpu", threads=1, log=None)
    assert sim.fluid.storage == "fp16" and sim.fluid.f.dtype == np.float16
    sim.step(2)
    sim.check_finite()  # a normal run is finite
    f = sim.backend.to_host(sim.fluid.f).copy()
    f[C27[:, 0] == 1, 5, 5, 5] = np.float16(65504.0)  # the 9 populations along +x: a velocity of ~18
    assert np.isfinite(f).all()
    sim.fluid.f = sim.backend.asarray(f)
    sim.step(1)
    assert np.isinf(sim.backend.to_host(sim.fluid.f)).any()
    with pytest.raises(SimulationDiverged) as err:
        sim.check_finite()
    assert err.value.solver == "fluid"


def test_a_checkpoint_keeps_fp16_and_refuses_another_storage(tmp_path):
    """fp16 populations are saved as float16 (the storage recorded in the scene, the metadata and the dtype)
    and restart bitwise; the same state into an fp32 scene is refused, naming fluid.storage."""
    import h5py

    from couplekit.io import CheckpointError, load_checkpoint
    from couplekit.io.checkpoint import _text_checksum
    from couplekit.scene import Scene
    from couplekit.simulation import Simulation

    sim = Simulation(Scene.from_dict(_tiny_fluid_fp16()), backend="cpu", threads=1, log=None)
    sim.step(3)
    path = sim.save(tmp_path / "fp16.h5")
    scene, states, meta = load_checkpoint(path)
    assert meta["fluid_storage"] == "fp16" and scene["fluid"]["storage"] == "fp16"
    assert states["fluid"]["f"].dtype == states["fluid"]["h"].dtype == np.float16
    again = Simulation.load(path, backend="cpu", threads=1, log=None)
    sim.step(2)
    again.step(2)
    assert np.array_equal(sim.backend.to_host(sim.fluid.f), again.backend.to_host(again.fluid.f))
    # the same file with its scene switched to fp32
    scene["fluid"]["storage"] = "fp32"
    with h5py.File(path, "r+") as f:
        text = __import__("json").dumps(scene)
        f.attrs["scene"] = text
        f.attrs["checksum"] = _text_checksum(text, f.attrs["meta"])
    with pytest.raises(CheckpointError) as err:
        Simulation.load(path, backend="cpu", threads=1, log=None)
    assert "fluid.storage" in str(err.value) and "fp16" in str(err.value)
