"""Fixtures of the coupling tests: the cpu backend (skipped, saying why, when there is no host compiler)."""

from __future__ import annotations

import pytest

from couplekit.backend import BackendUnavailableError, get_backend


@pytest.fixture(scope="session")
def cpu():
    try:
        return get_backend("cpu")
    except BackendUnavailableError as exc:  # pragma: no cover - CI has g++
        pytest.skip(f"cpu backend unavailable: {exc}")


@pytest.fixture(scope="session")
def cpu1():
    """The cpu backend on one OpenMP thread, for loops of thousands of launches on a few nodes."""
    try:
        return get_backend("cpu", threads=1)
    except BackendUnavailableError as exc:  # pragma: no cover - CI has g++
        pytest.skip(f"cpu backend unavailable: {exc}")
