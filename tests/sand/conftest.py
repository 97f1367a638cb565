"""Shared fixtures of the sand tests: the cpu backend (skipped when no host compiler) and the ops pair."""

from __future__ import annotations

import pytest

from couplekit.backend import BackendUnavailableError, get_backend
from couplekit.sand import KernelOps, ReferenceOps


@pytest.fixture(scope="session")
def cpu():
    try:
        return get_backend("cpu")
    except BackendUnavailableError as exc:  # pragma: no cover - CI always has g++
        pytest.skip(f"cpu backend unavailable: {exc}")


@pytest.fixture(scope="session")
def kops(cpu):
    return KernelOps(cpu)


@pytest.fixture(scope="session")
def rops():
    return ReferenceOps()
