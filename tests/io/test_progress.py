"""The progress bar's rate and ETA leave out the first steps, which load or compile the kernels (issue 17: a
first ETA of 56 s for a 12 s run), checked with a fake clock; and Simulation.run tells the bar when the first
steps are done."""

from __future__ import annotations

import io

import pytest

from couplekit.io.progress import ProgressBar


class FakeClock:
    """A clock the test advances by hand."""

    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def _bar(clock: FakeClock, total: int = 10, start: int = 0) -> ProgressBar:
    return ProgressBar(total, start, stream=io.StringIO(), clock=clock)


def test_compilation_is_left_out_of_rate_and_eta():
    """10 frames of 100 steps at 0.01 s a step; the first step compiles for 50 s. After frame 1 the ETA is the
    9 s left, not the 459 s that counting the compilation predicted."""
    clock = FakeClock()
    bar = _bar(clock)
    clock.now += 50.0 + 10 * 0.01  # the first chunk of 10 steps, compiling on the first
    bar.warmed(10)
    clock.now += 90 * 0.01  # the rest of frame 1
    line = bar.update(1, 100)
    assert bar.rate(100) == pytest.approx(100.0)
    assert bar.eta(1, 100) == pytest.approx(9.0)
    assert "100.0 steps/s" in line and "ETA 0:09" in line and "elapsed 0:51" in line  # elapsed keeps it all


def test_without_warm_up_every_step_counts():
    """A bar never told warmed() rates every step since it started (the behaviour before the fix)."""
    clock = FakeClock()
    bar = _bar(clock)
    clock.now += 51.0
    bar.update(1, 100)
    assert bar.rate(100) == pytest.approx(100 / 51.0)
    assert bar.eta(1, 100) == pytest.approx(51.0 * 9)


def test_no_timed_step_yet_shows_unknown():
    """A frame that ended with the warm-up chunk has no timed step: rate and ETA are unknown, then known."""
    clock = FakeClock()
    bar = _bar(clock, total=3)
    clock.now += 30.0
    bar.warmed(5)
    line = bar.update(1, 5)
    assert "? steps/s" in line and "ETA ?" in line
    clock.now += 0.5
    bar.update(2, 10)
    assert bar.rate(10) == pytest.approx(10.0) and bar.eta(2, 10) == pytest.approx(0.5)


def test_resumed_run_counts_frames_from_its_start_and_warms_once():
    clock = FakeClock()
    bar = _bar(clock, total=10, start=6)
    clock.now += 20.0
    bar.warmed(10)
    clock.now += 1.0
    bar.warmed(200)  # a later call does not move the mark
    clock.now += 1.0
    bar.update(8, 210)  # 2 frames of 105 steps, 200 timed steps in 2 s
    assert bar.rate(210) == pytest.approx(100.0)
    assert bar.eta(8, 210) == pytest.approx(2 * 105 / 100.0)


def test_simulation_run_marks_the_warm_up_after_its_first_steps(tmp_path, monkeypatch):
    from couplekit.scene import Scene
    from couplekit.simulation import Simulation

    calls = []
    monkeypatch.setattr(ProgressBar, "warmed", lambda self, steps: calls.append(steps))
    scene = Scene.from_dict(
        {
            "scene": {"name": "tiny"},
            "domain": {"size": [0.06, 0.06, 0.06], "dx": 0.005},
            "time": {"dt": 2e-4, "frame_duration": 1e-3, "frames": 2},
            "sand": {"youngs_modulus": 1e5, "particles_per_cell": 1},
            "bodies": [{"kind": "sand", "geometry": {"type": "box", "min": [0.02] * 3, "max": [0.04] * 3}}],
            "outputs": {"preview": False, "vtk": False, "ply": False, "checkpoint_every": 0},
        }
    )
    sim = Simulation(scene, backend="numpy")
    stream = io.StringIO()
    result = sim.run(out=tmp_path / "run", stream=stream)
    assert result.status == "done"
    assert calls == [sim.steps_per_frame]  # once, after the first chunk (a frame of 5 steps is one chunk)
    assert "frame 2/2" in stream.getvalue()
