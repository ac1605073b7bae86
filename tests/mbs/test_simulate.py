"""Modes (i), (ii), (iii) end to end (mbs.simulate), checked against dense sampling."""
import numpy as np
import pytest

from oracles.sampling import misses, sample_initial_points, trajectories
from mbs.errors import ModelError
from mbs.simulate import compare_modes, output_times, simulate, system_for, width_deviations
from verified.arith.interval import Interval

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
    with pytest.raises(ValueError, match="backward test needs first-order sets"):
        simulate("double_pendulum_paper", Interval(lo, hi), 1.0, set_order=2, backward_depth=2)


# --------------------------------------------------------------------------- issue 14, item 5
def test_wrong_keyword_names_simulate():
    lo, hi = pd.initial_box()
    with pytest.raises(TypeError, match=r"simulate\(\) got an unexpected keyword argument 'h_maxx'.*'h_max'"):
        simulate("pendulum_paper", Interval(lo, hi), 0.1, h_maxx=0.01)
    with pytest.raises(TypeError, match=r"^simulate\(\)"):
        simulate("pendulum_paper", Interval(lo, hi), 0.1, foo=1)
    # solve_ivp's names point to this API's
    with pytest.raises(TypeError, match=r"'t_eval' \(did you mean 'output_dt'\?\)"):
        simulate("pendulum_paper", Interval(lo, hi), 0.1, t_eval=[0.1])


def test_params_of_the_wrong_type_name_the_models_own_parameters():
    """``params`` as an Interval or a list: a one-line ValueError that shows the dict
    forms, including the paper model's own parameter names (was a TypeError from
    ``if params:`` on an Interval)."""
    lo, hi = dp.initial_box()
    for bad in (Interval([0.9], [1.1]), [1.0]):
        with pytest.raises(ValueError, match=r"must be a dict.*'m1': \[lo, hi\]") as e:
            simulate("double_pendulum_paper", Interval(lo, hi), 0.1, params=bad)
        assert "\n" not in str(e.value)


def test_progress_bar_by_default_only_when_interactive(monkeypatch):
    import io
    from mbs import progress
    made = []

    class Recorder(progress.Progress):
        def __init__(self, *a, **k):
            super().__init__(*a, **k)
            made.append(self)
    monkeypatch.setattr(progress, "Progress", Recorder)
    lo, hi = pd.initial_box()
    simulate("pendulum_paper", Interval(lo, hi), 0.1, mode="i")
    assert len(made) == 1 and made[0].calls == 0  # stderr is not a terminal here: no bar, no calls
    assert not progress.Progress(1.0, file=io.StringIO()).enabled
    made.clear()
    monkeypatch.setattr(progress, "interactive", lambda file=None: True)
    simulate("pendulum_paper", Interval(lo, hi), 0.1, mode="i")
    assert made[0].enabled and made[0].calls >= 1 and made[0].last_t == 0.1
    simulate("pendulum_paper", Interval(lo, hi), 0.1, mode="i", progress=False)
    assert not made[1].enabled and made[1].calls == 0


def test_interactive_detects_terminals():
    import io
    from mbs.progress import interactive

    class Tty(io.StringIO):
        def isatty(self):
            return True
    assert interactive(Tty()) and not interactive(io.StringIO())


@pytest.mark.slow  # (~5-8 s: the default run stays under 3 minutes)
def test_width_deviations_compare_every_output_time_and_say_which():
    lo, hi = pd.initial_box()
    sols = compare_modes("pendulum_paper", Interval(lo, hi), 0.2, modes=("i", "iii"), subdivision=[2, 2])
    a, b = sols["i"], sols["iii"]
    assert len(a.t) == 51  # compare_modes outputs 50 times by default, not only t_end
    dev = width_deviations(a, b)
    every = np.max(np.abs(a.hull.width() - b.hull.width()), axis=0)
    assert np.array_equal(np.asarray(dev), every) and dev.times.size == 51
    k = np.argmax(np.abs(a.hull.width() - b.hull.width()), axis=0)
    assert np.array_equal(dev.argmax_t, a.t[k]) and dev.only_one.size == 0
    assert "over 51 output times" in dev.describe()
    # one solution stopped earlier: compared where both are, the rest named
    short = simulate("pendulum_paper", Interval(lo, hi), 0.2, mode="i", subdivision=[2, 2], output_dt=0.004,
                     max_steps=3)
    assert short.status == "breakdown"
    dev = width_deviations(short, b)
    assert dev.times.size == len(short.t) and dev.only_one.size == 51 - len(short.t)
    assert "reached by one solution only" in dev.describe()


def test_ctrl_c_signal_stops_after_the_step_without_an_exception(capsys):
    """A real SIGINT during the integration (sent here from the progress callback at
    t >= 0.1; in a compiled kernel it used to surface as a numba SystemError) stops
    the run after that step: status "interrupted", everything verified so far kept."""
    import os
    import signal
    # a job started in the background (nohup, CI runners) inherits SIGINT ignored:
    # install Python's default handler for this test, as an interactive session has it
    old = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        _ctrl_c_run(capsys, os, signal)
    finally:
        signal.signal(signal.SIGINT, old)


def _ctrl_c_run(capsys, os, signal):
    sent = []

    def progress(t, t_end):
        if t >= 0.1 and not sent:
            sent.append(t)
            os.kill(os.getpid(), signal.SIGINT)
    lo, hi = pd.initial_box()
    sol = simulate("pendulum_paper", Interval(lo, hi), 0.3, mode="i", output_dt=0.1, progress=progress)
    assert sol.status == "interrupted" and sol.reason.startswith("interrupted (Ctrl-C)")
    assert sol.t_reached == sent[0] and 0.1 <= sol.t_reached < 0.3
    assert np.allclose(sol.t, [0.0, 0.1])
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler  # restored
    assert "Ctrl-C: stopping after the current step" in capsys.readouterr().err
