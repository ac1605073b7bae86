"""Modes (i), (ii), (iii) end to end (mbs.simulate), checked against dense sampling."""
import numpy as np
import pytest

from sampling import misses, sample_initial_points, trajectories
from mbs.errors import ModelError
from mbs.simulate import compare_modes, output_times, simulate, system_for, width_deviations
from verified.interval import Interval

from models import double_pendulum as dp
from models import pendulum as pd


def test_output_times_are_exact_multiples():
    ts = output_times(0.0, 1.0, 0.1)
    assert ts.size == 10 and ts[2] == 3 * 0.1 and ts[-1] == 1.0
    assert output_times(0.0, 1.05, 0.5).tolist() == [0.5, 1.0, 1.05]
    with pytest.raises(ValueError, match="output_dt"):
        output_times(0.0, 1.0, 0.0)


def test_paper_double_pendulum_in_all_three_modes_is_sound():
    lo, hi = dp.initial_box()
    sols = compare_modes("double_pendulum_paper", Interval(lo, hi), 0.3, output_dt=0.1,
                         subdivision=[4, 1, 1, 1], test_interval=0.05, test_splits=8)
    assert set(sols) == {"i", "ii", "iii"}
    samples = trajectories(lambda x: dp.rhs(x), sample_initial_points(lo, hi, 30), 0.3)
    for mode, sol in sols.items():
        assert sol.status == "completed", (mode, sol.reason)
        assert sol.mode == mode and len(sol.state_names) == 4
        assert np.allclose(sol.t, [0.0, 0.1, 0.2, 0.3])
        assert not misses(sol, samples, per_step=2), mode
        assert (sol.consistency is None) == (mode == "i")
    assert sols["iii"].stats["tests"] >= 5
    dev = width_deviations(sols["ii"], sols["iii"])
    assert dev.shape == (4,) and np.isfinite(dev).all()


def test_pendulum_mode_iii_simplified_is_conservative_and_sound():
    lo, hi = pd.initial_box()
    sol = simulate("pendulum_paper", Interval(lo, hi), 0.5, mode="iii", energy_rate="simplified",
                   output_dt=0.25, test_splits=16)
    assert sol.status == "completed"
    assert system_for("pendulum_paper", "iii", energy_rate="simplified").conservative
    samples = trajectories(lambda x: pd.rhs(x), sample_initial_points(lo, hi, 30), 0.5)
    assert not misses(sol, samples, per_step=2)


@pytest.mark.slow  # ~27 s on an idle 2-core machine
def test_damped_urdf_robot_with_an_uncertain_angle():
    """example-robot-data's double pendulum (damping 0.05 on both joints): dH/dt =
    -qd^T D qd enters H_V (mode ii derives it by differentiation, mode iii takes the
    symbolic chain rule); both enclose the sampled damped trajectories."""
    from models.robots import double_pendulum

    chain = double_pendulum()
    num = chain.numeric()
    # q = 0 is the upright position of this URDF; it hangs at q1 = pi
    lo = np.array([np.pi - 0.3, 0.0, 0.0, 0.0])
    hi = np.array([np.pi - 0.29, 0.0, 0.0, 0.0])
    samples = trajectories(lambda x: num.rhs(list(x)), sample_initial_points(lo, hi, 12), 0.2)
    for mode in ("ii", "iii"):
        sol = simulate(chain, Interval(lo, hi), 0.2, mode=mode, output_dt=0.1, test_interval=0.05, test_splits=8,
                       subdivision=[2, 1, 1, 1])
        assert sol.status == "completed", sol.reason
        assert sol.stats["tests"] >= 3
        assert not misses(sol, samples, per_step=2), mode


def test_clear_errors():
    lo, hi = dp.initial_box()
    with pytest.raises(ValueError, match="mode"):
        simulate("double_pendulum_paper", Interval(lo, hi), 1.0, mode="iv")
    with pytest.raises(ValueError, match="4 states"):
        simulate("double_pendulum_paper", Interval([0.0, 0.0], [1.0, 1.0]), 1.0)
    with pytest.raises(ValueError, match="t_end"):
        simulate("double_pendulum_paper", Interval(lo, hi), -1.0)
    with pytest.raises(ModelError, match="unknown model"):
        simulate("no_such_robot", Interval(lo, hi), 1.0)
    with pytest.raises(ValueError, match="split_strategy"):
        simulate("double_pendulum_paper", Interval(lo, hi), 1.0, split_strategy="random")
    with pytest.raises(ValueError, match="mode i"):
        simulate("double_pendulum_paper", Interval(lo, hi), 1.0, mode="i", constraints=[object()])
