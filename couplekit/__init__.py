"""couplekit: air-water-sand mixtures, a lattice Boltzmann two-phase fluid coupled with MPM sand.

One CUDA C kernel source per solver stage runs on a GPU (CuPy), on the CPU (host C++ build with OpenMP),
and has a NumPy reference; see :mod:`couplekit.backend`.
"""

from __future__ import annotations

from .backend import Backend, BackendUnavailableError, KernelArgumentError, KernelBuildError, get_backend

__version__ = "0.1.0"

__all__ = [
    "Backend",
    "BackendUnavailableError",
    "KernelArgumentError",
    "KernelBuildError",
    "__version__",
    "get_backend",
]

# The scripting API (DESIGN "Scenes, API, outputs"): ck.Scene.load(path), ck.Simulation(scene, backend="auto").
from .scene import Scene, SceneError  # noqa: E402
from .simulation import Simulation, SimulationDiverged  # noqa: E402

__all__ += ["Scene", "SceneError", "Simulation", "SimulationDiverged"]
