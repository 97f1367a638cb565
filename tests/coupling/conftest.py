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
