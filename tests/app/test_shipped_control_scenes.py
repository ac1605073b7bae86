"""The shipped UR5 quintic scene (models/scenes/ur5_quintic.toml: no solver settings,
method "auto") run as the CLI runs it, on a short horizon, against the sampled oracle of
benchmarks/bench_control.py: Pinocchio aba with the sampled payload on the plant, the
controller in floats, DOP853; tool positions by Pinocchio's forward kinematics."""
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))

import bench_control  # noqa: E402


@pytest.mark.slow  # ~15 s: 0.3 s of the quintic (about 20 UR5 steps) and 12 closed-loop samples
def test_shipped_ur5_quintic_scene_encloses_the_sampled_closed_loop(monkeypatch):
    monkeypatch.setitem(bench_control.TARGET_T, "ur5_quintic", 0.3)
    row = bench_control.run_case("quintic", "ur5_quintic", 120.0, None, None, samples=12)
    assert row["status"] == "completed" and row["t_reached"] == pytest.approx(0.3)
    assert row["inside"] and row["frame_inside"]
    # the scene as shipped names no method: "auto" picks the composition step
    from mbs.app.scene import load_scene
    assert load_scene("ur5_quintic").solver == {}


@pytest.mark.slow
def test_the_closed_loop_oracle_bites(monkeypatch):
    """The same run with every output box narrowed to 90 % about its midpoint: sampled
    states must fall outside, so the check above can fail."""
    import mbs.simulate
    from oracles.mutants import narrows_output_boxes
    monkeypatch.setattr(mbs.simulate, "solve", narrows_output_boxes(mbs.simulate.solve))
    monkeypatch.setitem(bench_control.TARGET_T, "ur5_quintic", 0.3)
    row = bench_control.run_case("quintic", "ur5_quintic", 120.0, None, None, samples=12)
    assert not row["inside"]


@pytest.mark.slow  # ~15 s: 0.5 s of the hold (about 10 Panda steps) and 12 closed-loop samples
def test_shipped_panda_hold_scene_encloses_the_sampled_closed_loop(monkeypatch):
    """The Panda's URDF has joint damping (0.003 N m s/rad), which Pinocchio's aba leaves
    out: the oracle applies it (mbs.app.sampling.plant_acceleration), and the composition
    step's enclosure holds every sample and tool position."""
    monkeypatch.setitem(bench_control.TARGET_T, "panda_pd_hold", 0.5)
    row = bench_control.run_case("panda hold", "panda_pd_hold", 120.0, None, None, samples=12,
                                 frame="panda_hand_tcp")
    assert row["status"] == "completed" and row["t_reached"] == pytest.approx(0.5)
    assert row["inside"] and row["frame_inside"]
