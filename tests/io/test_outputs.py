"""Outputs read back: .vti/.vtp/.pvd through pyvista, PLY, JSON lines, HDF5 checkpoints, PNG previews."""

from __future__ import annotations

import math

import numpy as np
import pytest

from couplekit.io import (
    CheckpointError,
    DiagnosticsLog,
    PvdIndex,
    load_checkpoint,
    read_diagnostics,
    read_ply,
    read_pvd,
    render_preview,
    save_checkpoint,
    write_fields_vti,
    write_particles_ply,
    write_particles_vtp,
)

pv = pytest.importorskip("pyvista")
RNG = np.random.default_rng(3)


def test_vti_fields_read_back_at_cell_centres(tmp_path):
    nz, ny, nx, dx = 4, 5, 6, 0.01
    phi = RNG.random((nz, ny, nx)).astype(np.float32)
    vel = RNG.random((3, nz, ny, nx)).astype(np.float32)
    solid = RNG.random((nz, ny, nx)) > 0.5
    path = write_fields_vti(tmp_path / "f.vti", {"phi": phi, "velocity": vel, "solid": solid}, dx)
    g = pv.read(path)
    assert g.dimensions == (nx, ny, nz)
    np.testing.assert_allclose(g.origin, [dx / 2] * 3)
    # cell (x=2, y=3, z=1): VTK point id x + nx*(y + ny*z), position (i + ½) dx
    pid = 2 + nx * (3 + ny * 1)
    np.testing.assert_allclose(g.points[pid], [2.5 * dx, 3.5 * dx, 1.5 * dx], rtol=1e-6)
    assert g.point_data["phi"][pid] == phi[1, 3, 2]
    np.testing.assert_array_equal(g.point_data["velocity"][pid], vel[:, 1, 3, 2])
    assert g.point_data["solid"][pid] == solid[1, 3, 2]


def test_vtp_particles_and_pvd_index(tmp_path):
    x = RNG.random((3, 50)).astype(np.float32)
    sat = RNG.random(50).astype(np.float32)
    index = PvdIndex(tmp_path / "particles.pvd")
    for frame in range(3):
        f = write_particles_vtp(tmp_path / f"particles_{frame:04d}.vtp", x + frame, {"saturation": sat, "v": x})
        index.add(0.1 * frame, f)
    entries = read_pvd(tmp_path / "particles.pvd")
    assert [e[1] for e in entries] == [f"particles_{i:04d}.vtp" for i in range(3)]
    assert entries[2][0] == pytest.approx(0.2)
    cloud = pv.read(tmp_path / entries[2][1])
    np.testing.assert_allclose(cloud.points, (x + 2).T)
    np.testing.assert_array_equal(cloud.point_data["saturation"], sat)
    assert cloud.n_cells == 50  # vertex cells, so ParaView shows the points
    series = pv.get_reader(str(tmp_path / "particles.pvd"))
    assert len(series.time_values) == 3
    # a resumed run restarting at t = 0.1 drops later entries and appends
    again = PvdIndex(tmp_path / "particles.pvd")
    again.add(0.1, tmp_path / "particles_0001.vtp")
    assert [e[0] for e in read_pvd(tmp_path / "particles.pvd")] == [0.0, 0.1]


def test_ply_round_trip_and_meshio(tmp_path):
    x = RNG.random((3, 20))
    v = RNG.random((3, 20))
    m = RNG.random(20)
    path = write_particles_ply(tmp_path / "p.ply", x, {"moisture": m, "v": v})
    back = read_ply(path)
    np.testing.assert_array_equal(back["x"], x[0].astype(np.float32))
    np.testing.assert_array_equal(back["v_2"], v[2].astype(np.float32))
    np.testing.assert_array_equal(back["moisture"], m.astype(np.float32))
    import meshio

    mesh = meshio.read(path)  # an independent reader
    np.testing.assert_allclose(mesh.points, x.T.astype(np.float32))


def test_diagnostics_json_lines(tmp_path):
    with DiagnosticsLog(tmp_path / "d.jsonl") as log:
        log.write({"frame": 0, "time": 0.0, "x": np.float64(1.5)})
        log.write({"frame": 1, "time": 0.1, "x": float("nan"), "y": float("inf")})
    with DiagnosticsLog(tmp_path / "d.jsonl", append=True) as log:
        log.write({"frame": 2})
    recs = read_diagnostics(tmp_path / "d.jsonl")
    assert [r["frame"] for r in recs] == [0, 1, 2]
    assert recs[0]["x"] == 1.5 and math.isnan(recs[1]["x"]) and recs[1]["y"] == math.inf


def test_checkpoint_round_trip_is_bitwise(tmp_path):
    states = {"fluid": {"f": RNG.random((27, 4, 4, 4)).astype(np.float32), "step_count": np.array(7, np.int64)}}
    scene = {"domain": {"size": [1, 1, 1]}}
    save_checkpoint(tmp_path / "c.h5", scene, states, {"step": 7, "backend": "cpu"})
    sc, st, meta = load_checkpoint(tmp_path / "c.h5")
    assert sc == scene and meta["step"] == 7
    assert st["fluid"]["f"].dtype == np.float32 and st["fluid"]["f"].tobytes() == states["fluid"]["f"].tobytes()
    assert int(st["fluid"]["step_count"]) == 7
    assert not (tmp_path / "c.h5.tmp").exists()
    (tmp_path / "junk.h5").write_bytes(b"not hdf5")
    with pytest.raises(CheckpointError, match="not a readable HDF5"):
        load_checkpoint(tmp_path / "junk.h5")


def test_preview_renders_headless(tmp_path):
    """Off-screen rendering works here (EGL); the picture has the water and the particles in it."""
    n = 16
    z = (np.arange(n) + 0.5)[:, None, None] * np.ones((n, n, n))
    phi = (z < 6).astype(np.float32)
    x = RNG.uniform(0.3, 0.7, (3, 300)) * n * 0.01
    path = render_preview(tmp_path / "p.png", (0.16, 0.16, 0.16), 0.01, {"phi": phi}, {"x": x, "v": x}, title="t = 0")
    from PIL import Image

    img = np.asarray(Image.open(path).convert("RGB")).astype(int)
    assert img.shape == (600, 800, 3)
    blue = (img[..., 2] > img[..., 0] + 40).sum()
    assert blue > 1000, "the water surface should show"
    assert (img.std(axis=(0, 1)) > 10).all()
