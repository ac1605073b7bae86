"""The solver as a driver loop: StepResult, set module, policies, the hook protocol,
stopping early (a hook's stop, KeyboardInterrupt, StopAfterWall) and rollback.

Runs are compared bit for bit with an unhooked run of the same problem: hooks that
change nothing must change no number, and a stopped or interrupted run must return
exactly the prefix of the full run.
"""
import itertools

import numpy as np
import pytest

from oracles.sampling import misses, sample_initial_points, trajectories
from verified.steppers import lohner
from verified.sets import first_order
from verified.consistency.energy_test import EnergyTest
from verified.graph import trace
from verified.driver.hooks import Hook, RunSetup, SolverHook, StopAfterWall, check_hooks
from verified.arith.interval import Interval
from verified.driver.control import LANDING_STRETCH, StepControl, WrapControl
from verified.sets.bases import AutoBasis, QRBasis, error_basis_policy
from verified.sets.first_order import DoubletonSets
from verified.sets.protocol import SetBatch
from verified.methods import METHOD_FIELDS
from verified.solver import VerifiedODE, solve as _solve
from verified.steppers.protocol import StepResult

from models import pendulum as pd



def solve(*a, **k):  # these tests exercise the QR-Lohner driver (the default before method="auto")
    if "method" not in k and not any(f in k for f in METHOD_FIELDS):
        k["method"] = "lohner"
    return _solve(*a, **k)


NAMES = ["q", "qd"]
T_EVAL = [0.2, 0.4, 0.6]


@pytest.fixture(scope="module")
def ode():
    return VerifiedODE(trace(pd.rhs, 2, input_names=NAMES))


@pytest.fixture(scope="module")
def box():
    lo, hi = pd.initial_box()
    return Interval(lo, hi)


@pytest.fixture(scope="module")
def reference(ode, box):
    """The unhooked run every hooked run is compared with."""
    return solve(ode, box, (0.0, 0.6), t_eval=T_EVAL, subdivision=[2, 2])


def _same_bits(a: Interval, b: Interval) -> bool:
    return np.array_equal(a.lo, b.lo) and np.array_equal(a.hi, b.hi)


def _assert_prefix(part, full, steps):
    """``part`` holds exactly the first ``steps`` steps of ``full`` (and its outputs up to there)."""
    assert len(part.tube) == steps and part.tube_t.size == steps + 1
    assert np.array_equal(part.tube_t, full.tube_t[: steps + 1])
    assert all(_same_bits(a, b) for a, b in zip(part.tube, full.tube))
    assert part.t_reached == full.tube_t[steps]
    k = len(part.t)
    assert k >= 1 and np.array_equal(part.t, full.t[:k]) and part.t[-1] <= part.t_reached
    assert all(_same_bits(a, b) for a, b in zip(part.boxes, full.boxes[:k]))


class Recorder(Hook):
    def __init__(self):
        self.setups, self.steps, self.solutions = [], [], []

    def before_run(self, setup):
        self.setups.append(setup)

    def after_step(self, step, sets, run):
        self.steps.append((step, sets.n_sets))

    def after_run(self, solution):
        self.solutions.append(solution)


# ----------------------------------------------------------------------------- structure
def test_sets_live_in_their_module_and_old_imports_keep_working():
    assert lohner.DoubletonSets is first_order.DoubletonSets is DoubletonSets
    s = DoubletonSets.from_boxes(Interval([[0.0, 1.0]], [[0.5, 1.5]]))
    assert isinstance(s, SetBatch)
    assert isinstance(EnergyTest(trace(lambda x, p: [x[0] * x[1]], 2)), SolverHook)
    assert isinstance(StopAfterWall(1.0), SolverHook)


@pytest.mark.parametrize("order,step", [(1, "mean_value"), (2, "mean_value"), (2, "composition")])
def test_the_set_kind_comes_from_the_registry(ode, box, monkeypatch, order, step):
    """solve() takes the sets type and the stepper from verified.steppers.set_kinds.SET_KINDS
    (issue 15: a new representation is an entry there, not a branch in the solver): an
    entry replaced by a recording one is what runs, and gives the same numbers."""
    from verified.steppers import set_kinds
    plain = solve(ode, box, (0.0, 0.2), t_eval=[0.2], set_order=order, set_step=step)
    real = set_kinds.SET_KINDS[(order, step)]
    made = []

    class Recorded(real.sets):
        pass

    def stepper(*args):
        made.append(real.stepper(*args))
        return made[-1]

    monkeypatch.setitem(set_kinds.SET_KINDS, (order, step), set_kinds.SetKind(Recorded, stepper))
    seen = []
    sol = solve(ode, box, (0.0, 0.2), t_eval=[0.2], set_order=order, set_step=step,
                hooks=[type("H", (Hook,), {"before_run": lambda self, setup: seen.append(type(setup.sets))})()])
    assert made and seen == [Recorded]
    assert _same_bits(sol.boxes[-1], plain.boxes[-1])


def test_an_unknown_set_kind_is_a_one_line_error():
    from verified.steppers.set_kinds import set_kind
    with pytest.raises(ValueError, match="no set kind for set_order=1, set_step='composition' .known: "):
        set_kind(1, "composition")


def test_the_stepper_returns_a_step_result(ode, box):
    st = lohner.LohnerStepper(ode.taylor, ode.variational, 12)
    s = DoubletonSets.from_boxes(box.reshape((1, 2)))
    X = s.hull()
    cX = st.coefficients(X)
    E, cE = st.apriori(X, cX, 0.01)
    res = st.step(s, 0.01, X, E, cE)
    assert isinstance(res, StepResult)
    assert res.previous is s and res.sets.n_sets == 1 and res.h == 0.01 and res.length == 0.01
    assert res.nonlinear_width.shape == (1, 2) and (res.nonlinear_width >= 0).all()
    assert _same_bits(res.tube, E) and _same_bits(res.hull, X)
    # the new sets lie in the a-priori enclosure over the step
    assert res.sets.hull().issubset(E).all()


def test_a_recording_hook_sees_every_step_and_changes_nothing(ode, box, reference):
    rec = Recorder()
    sol = solve(ode, box, (0.0, 0.6), t_eval=T_EVAL, subdivision=[2, 2], hooks=[rec])
    assert len(rec.setups) == 1 and isinstance(rec.setups[0], RunSetup) and rec.solutions == [sol]
    assert rec.setups[0].sets.n_sets == 4 and rec.setups[0].n_state == rec.setups[0].n_steer == 2
    _assert_prefix(sol, reference, reference.stats["steps"])
    assert sol.stats == {**reference.stats, "wall_s": sol.stats["wall_s"]}
    assert len(rec.steps) == reference.stats["steps"]
    for j, (step, nb) in enumerate(rec.steps):
        assert step.t_start == reference.tube_t[j] and step.t == reference.tube_t[j + 1]
        assert float(step.t_exact_start) <= step.t_start <= step.t  # (t_start rounds t_exact_start)
        assert step.t_enclosure.lo <= step.t_exact <= step.t_enclosure.hi
        assert _same_bits(step.tube, reference.tube[j]) and nb == 4
    assert [s.t for s, _ in rec.steps if s.landed] == T_EVAL


def test_a_hook_that_replaces_the_sets_by_equal_ones_changes_no_bit(ode, box, reference):
    class Copy(Hook):
        def after_step(self, step, sets, run):
            return sets.take(np.arange(sets.n_sets))

    sol = solve(ode, box, (0.0, 0.6), t_eval=T_EVAL, subdivision=[2, 2], hooks=[Copy()])
    _assert_prefix(sol, reference, reference.stats["steps"])


def test_the_driver_continues_from_the_sets_a_hook_returns(ode, box):
    """A hook that refines (splits every set once, at 0.2 s): the run carries the parts
    on, and the sampled trajectories stay inside."""
    class SplitOnce(Hook):
        done = False

        def after_step(self, step, sets, run):
            if step.landed and not self.done:
                self.done = True
                return sets.split(np.ones(sets.n_sets, dtype=bool))
            return None

    sol = solve(ode, box, (0.0, 0.6), t_eval=T_EVAL, subdivision=[2, 2], hooks=[SplitOnce()])
    assert sol.success and sol.stats["final_boxes"] == 8 and sol.stats["max_boxes"] == 8
    assert sol.boxes[1].shape[0] == 8  # the output at 0.2 is taken after the hook
    lo, hi = pd.initial_box()
    assert misses(sol, trajectories(lambda x: pd.rhs(x), sample_initial_points(lo, hi, 10), 0.6), per_step=2) == []


def test_a_hook_removing_every_set_is_a_breakdown(ode, box):
    class Empty(Hook):
        def after_step(self, step, sets, run):
            return sets.take(np.zeros(0, dtype=int))

    sol = solve(ode, box, (0.0, 0.6), t_eval=T_EVAL, hooks=[Empty()])
    assert sol.status == "breakdown" and "removed every set" in sol.reason
    assert sol.stats["steps"] == 1 and len(sol.tube) == 1


def test_a_set_update_that_cannot_be_inverted_is_a_breakdown(ode, box, reference, monkeypatch):
    """A SingularMatrixError inside a step (a set so wide that its basis or recentring
    cannot be inverted: seen on the UR5 with second-order sets) ends the run as a
    break-down holding exactly the steps verified before it, not as an exception."""
    from verified.arith.linalg import SingularMatrixError

    calls = {"n": 0}
    real = lohner.LohnerStepper.step

    def failing(self, *args, **kwargs):
        calls["n"] += 1
        if calls["n"] == 4:
            raise SingularMatrixError("cannot verify 1 of 1 linear systems", [(0,)])
        return real(self, *args, **kwargs)

    monkeypatch.setattr(lohner.LohnerStepper, "step", failing)
    sol = solve(ode, box, (0.0, 0.6), t_eval=T_EVAL, subdivision=[2, 2])
    assert sol.status == "breakdown" and "set update failed" in sol.reason and "cannot verify" in sol.reason
    _assert_prefix(sol, reference, 3)


# ----------------------------------------------------------------------------- stopping early
class StopAt(Hook):
    def __init__(self, k, exc=None):
        self.k, self.exc, self.seen = k, exc, 0

    def after_step(self, step, sets, run):
        self.seen += 1
        if self.seen == self.k:
            if self.exc is not None:
                raise self.exc
            run.stop(f"asked at step {self.k}")


@pytest.mark.parametrize("k", [1, 3])
def test_a_stop_request_returns_the_verified_prefix(ode, box, reference, k):
    after = Recorder()
    sol = solve(ode, box, (0.0, 0.6), t_eval=T_EVAL, subdivision=[2, 2], hooks=[StopAt(k), after])
    assert sol.status == "stopped" and sol.reason == f"asked at step {k}" and not sol.success
    assert sol.stats["steps"] == k
    assert len(after.steps) == k - 1  # hooks after the stopping one are not called on its step
    _assert_prefix(sol, reference, k)


def test_a_stop_on_a_step_that_lands_keeps_its_output(ode, box, reference):
    landing = next(j for j in range(len(reference.tube_t)) if reference.tube_t[j] == T_EVAL[0])
    sol = solve(ode, box, (0.0, 0.6), t_eval=T_EVAL, subdivision=[2, 2], hooks=[StopAt(landing)])
    assert sol.status == "stopped" and sol.t[-1] == T_EVAL[0] == sol.t_reached
    _assert_prefix(sol, reference, landing)


@pytest.mark.parametrize("k", [1, 4])
def test_keyboard_interrupt_returns_the_verified_prefix(ode, box, reference, k):
    sol = solve(ode, box, (0.0, 0.6), t_eval=T_EVAL, subdivision=[2, 2], hooks=[StopAt(k, KeyboardInterrupt())])
    assert sol.status == "interrupted" and "KeyboardInterrupt" in sol.reason
    _assert_prefix(sol, reference, k)


def test_keyboard_interrupt_in_the_progress_callback(ode, box, reference):
    calls = []

    def progress(t, t_end):
        calls.append(t)
        if len(calls) == 2:
            raise KeyboardInterrupt

    sol = solve(ode, box, (0.0, 0.6), t_eval=T_EVAL, subdivision=[2, 2], progress=progress)
    assert sol.status == "interrupted"
    _assert_prefix(sol, reference, 2)


def test_other_exceptions_from_hooks_propagate(ode, box):
    with pytest.raises(ZeroDivisionError):
        solve(ode, box, (0.0, 0.6), hooks=[StopAt(2, ZeroDivisionError())])


def test_stop_after_wall_with_a_fake_clock(ode, box, reference):
    ticks = itertools.count()  # before_run reads 0, the k-th step reads k
    sol = solve(ode, box, (0.0, 0.6), t_eval=T_EVAL, subdivision=[2, 2],
                hooks=[StopAfterWall(2.5, clock=lambda: float(next(ticks)))])
    assert sol.status == "stopped" and "2.5 s" in sol.reason
    _assert_prefix(sol, reference, 3)


def test_stop_after_wall_zero_stops_after_the_first_step_and_huge_never(ode, box, reference):
    sol = solve(ode, box, (0.0, 0.6), t_eval=T_EVAL, subdivision=[2, 2], hooks=[StopAfterWall(0.0)])
    assert sol.status == "stopped"
    _assert_prefix(sol, reference, 1)
    sol = solve(ode, box, (0.0, 0.6), t_eval=T_EVAL, subdivision=[2, 2], hooks=[StopAfterWall(np.inf)])
    assert sol.status == "completed"


def test_bad_hooks_are_refused_in_one_line_before_any_work(box, monkeypatch):
    import verified.driver.batch as batch_mod  # (the one-batch driver solve runs)

    def no_work(*a, **k):
        raise AssertionError("work started before the hooks were checked")

    monkeypatch.setattr(batch_mod, "TaylorODE", no_work)
    monkeypatch.setattr(batch_mod, "_stepper", no_work)
    g = trace(pd.rhs, 2, input_names=NAMES)
    for bad in (object(), "hook", 3):
        with pytest.raises(ValueError) as info:
            solve(g, box, (0.0, 0.6), hooks=[bad] if bad != 3 else bad)
        assert "\n" not in str(info.value) and "hook" in str(info.value)
    with pytest.raises(ValueError, match="seconds"):
        StopAfterWall(-1.0)
    with pytest.raises(ValueError, match="seconds"):
        StopAfterWall(float("nan"))
    assert check_hooks(None) == []


# ----------------------------------------------------------------------------- rollback
def test_rollback_returns_the_step_before_and_is_refused_where_it_must_be(ode, box, reference):
    calls, landed_refusals = [], []

    class Back(Hook):
        def after_step(self, step, sets, run):
            calls.append(step.t)
            if len(calls) == 1:
                assert run.rollback() is None  # nothing before the first step
            elif len(calls) == 2:
                n_tube = len(run.tube)
                prev, prev_sets = run.rollback()
                assert prev.t == step.t_start == reference.tube_t[1] and prev_sets is step.previous
                assert len(run.tube) == n_tube - 1 and run.tube_t[-1] == prev.t
                assert run.rollback() is None  # one step back at most
                return prev_sets.take(np.arange(prev_sets.n_sets))  # (where a test would prune)
            elif step.landed:
                landed_refusals.append(run.rollback())
            return None

    sol = solve(ode, box, (0.0, 0.6), t_eval=T_EVAL, subdivision=[2, 2], hooks=[Back()])
    assert sol.success and landed_refusals == [None] * len(T_EVAL)
    assert len(sol.tube) == sol.stats["steps"] - 1 and (np.diff(sol.tube_t) > 0).all()
    assert sol.tube_t[1] == reference.tube_t[1] and _same_bits(sol.tube[0], reference.tube[0])
    lo, hi = pd.initial_box()
    assert misses(sol, trajectories(lambda x: pd.rhs(x), sample_initial_points(lo, hi, 10), 0.6), per_step=2) == []


def test_the_energy_test_as_a_hook_equals_the_consistency_argument(ode, box):
    H = trace(lambda x, p: [pd.hamiltonian(x)], 2, input_names=NAMES)

    def run(kw):
        test = EnergyTest(H, "derive", test_interval=0.05, test_splits=8, min_gain=0.0)
        return solve(ode, box, (0.0, 0.3), t_eval=[0.1, 0.2, 0.3], **kw(test))

    a = run(lambda t: dict(consistency=t))
    b = run(lambda t: dict(hooks=[t]))
    assert a.stats["tests"] >= 5 and a.stats["pruned_boxes"] > 0
    assert {k: v for k, v in a.stats.items() if not k.endswith("_s")} == \
        {k: v for k, v in b.stats.items() if not k.endswith("_s")}
    assert all(_same_bits(x, y) for x, y in zip(a.tube, b.tube)) and len(a.tube) == len(b.tube)
    assert np.array_equal(a.consistency.ra, b.consistency.ra)


# ----------------------------------------------------------------------------- policies
def test_policies():
    assert isinstance(error_basis_policy("qr"), QRBasis) and isinstance(error_basis_policy("auto"), AutoBasis)
    with pytest.raises(ValueError, match="error_basis"):
        error_basis_policy("lu")
    assert error_basis_policy(AutoBasis()).name == "auto"

    class FakeStepper:
        order = 4

        def suggest_step(self, cX, tol, components=None):
            return 0.3

    c = StepControl(tol=1e-10, h_min=1e-9, h_max=1.0, steer=2)
    assert c.propose(FakeStepper(), None, np.inf, 0.5, 0.5) == 0.3
    assert c.propose(FakeStepper(), None, 0.1, 0.5, 0.5) == 0.1
    assert c.propose(FakeStepper(), None, np.inf, 0.25, 0.25 + 2**-54) == 0.25 + 2**-54  # lands
    # a gap up to LANDING_STRETCH x the step is taken in one step (no sliver left behind)
    assert c.propose(FakeStepper(), None, np.inf, 0.35, 0.35) == 0.35
    assert c.propose(FakeStepper(), None, np.inf, 0.3 * LANDING_STRETCH * 1.01, 0.3 * LANDING_STRETCH * 1.01) == 0.3
    # ... but never past h_max, and past the wrapping limit only by the same factor
    assert StepControl(tol=1e-10, h_min=1e-9, h_max=0.32, steer=2).propose(FakeStepper(), None, np.inf, 0.35, 0.35) == 0.3
    assert c.propose(FakeStepper(), None, 0.2, 0.23, 0.23) == 0.23
    assert c.propose(FakeStepper(), None, 0.2, 0.25, 0.25) == 0.2

    class FakeStep:
        def __init__(self, nl, lin):
            self.nonlinear_width = np.array([[nl, 0.0]])
            self.sets = type("S", (), {"linear_width": lambda self: np.array([[lin, 1.0]])})()
            self.length = 0.1

    w = WrapControl(target=0.03, h_max=0.15, steer=2)
    w.update(FakeStep(0.12, 1.0))  # ratio 0.12 = 4 x target: h / 2
    assert w.h_limit == pytest.approx(0.05)
    for _ in range(5):
        w.update(FakeStep(0.0, 1.0))
    assert w.h_limit == 0.15  # grows back by doubling, never beyond h_max


class _TubeStepper:
    """apriori over [0, h] returns a fresh (E, cE) whose order-K coefficient is ``mag``."""
    order = 4

    def __init__(self, mag, fail_above=np.inf):
        self.mag, self.fail_above, self.calls = mag, fail_above, []

    def apriori(self, X, cX, h):
        self.calls.append(h)
        if h > self.fail_above:
            return None
        cE = Interval(np.full((1, self.order + 1, 2), -self.mag), np.full((1, self.order + 1, 2), self.mag))
        return Interval(np.zeros((1, 2)), np.ones((1, 2))), cE


def test_a_step_shrunk_for_its_remainder_keeps_its_enclosure():
    """The remainder control shrinks a step whose Lagrange remainder ``|x_[K](E)| h^K``
    is above ``remainder_slack * tol`` without a second a-priori test: the enclosure over
    [0, h] holds over every shorter step. The step returned is never longer than the one
    its enclosure was validated for, and its remainder is within the limit."""
    c = StepControl(tol=1e-10, h_min=1e-9, h_max=1.0, steer=2)
    limit = c.remainder_slack * c.tol
    h0 = 0.1
    st = _TubeStepper(mag=3.0 * limit / h0**4)  # remainder 3 x the limit at h0
    found = c.validate(st, None, None, h0)
    assert st.calls == [h0] and found.evaluations == 1 and found.rejected == 1
    assert found.h < h0 and st.mag * found.h**4 <= limit
    # far above the limit (the shrink factor is capped at 0.2): a fresh test at the shorter step
    st = _TubeStepper(mag=1e6 * limit / h0**4)
    found = c.validate(st, None, None, h0)
    assert len(st.calls) >= 2 and st.calls[1] == pytest.approx(0.2 * h0)
    assert found.h <= st.calls[-1] and st.mag * found.h**4 <= limit
    # an enclosure that failed at h0 is never kept: the halved step is tested afresh
    st = _TubeStepper(mag=limit / h0**4, fail_above=0.75 * h0)
    found = c.validate(st, None, None, h0)
    assert st.calls == [h0, 0.5 * h0] and found.h == 0.5 * h0


def test_a_kept_enclosure_encloses_the_sampled_trajectories(monkeypatch):
    """Laub-Loomis (W = 0.01, `auto`): steps shrunk for their remainder take the
    enclosure validated over the longer step (checked to happen here), and every
    sampled trajectory (DOP853) stays in the output boxes and the step tubes."""
    import verified.driver.control as control

    def f(x, p):
        x1, x2, x3, x4, x5, x6, x7 = x
        return [1.4 * x3 - 0.9 * x1, 2.5 * x5 - 1.5 * x2, 0.6 * x7 - 0.8 * x2 * x3, 2 - 1.3 * x3 * x4,
                0.7 * x1 - x4 * x5, 0.3 * x1 - 3.1 * x6, 1.8 * x6 - 1.5 * x2 * x7]
    c0 = np.array([1.2, 1.05, 1.5, 2.4, 1, 0.1, 0.45])
    x0 = Interval(c0 - 0.01, c0 + 0.01)
    kept = []
    validate = control.StepControl.validate

    def counting(self, stepper, X, cX, h):
        found = validate(self, stepper, X, cX, h)
        kept.append(found.enclosure is not None and found.evaluations == found.rejected)
        return found
    monkeypatch.setattr(control.StepControl, "validate", counting)
    sol = _solve(trace(f, 7), x0, (0.0, 20.0), t_eval=np.linspace(1.0, 20.0, 20))
    assert sol.status == "completed" and any(kept)

    def rhs(x):
        return np.array(f(x, None), float)
    pts = sample_initial_points(x0.lo, x0.hi, 24, seed=3, corner_limit=16)
    assert misses(sol, trajectories(rhs, pts, 20.0)) == []


def test_a_stop_after_the_last_output_is_a_completed_run(ode, box, reference):
    sol = solve(ode, box, (0.0, 0.6), t_eval=T_EVAL, subdivision=[2, 2], hooks=[StopAt(reference.stats["steps"])])
    assert sol.status == "completed" and sol.reason == ""
    _assert_prefix(sol, reference, reference.stats["steps"])


def test_adaptive_splitting_after_a_pruning_hook_is_sound():
    """Adaptive splitting with the energy test: the split mask comes from the step's
    widths, which describe the sets before the test replaced them by its parts. Applied
    to the parts it dropped every part beyond the mask's length (sampled states
    outside the enclosure); now nothing is split after a step whose sets a hook replaced."""
    rhs = trace(pd.rhs, 2, input_names=NAMES)
    H = trace(lambda x, p: [pd.hamiltonian(x)], 2, input_names=NAMES)
    lo, hi = pd.initial_box()
    test = EnergyTest(H, "derive", test_interval=0.1, test_splits=16, min_gain=0.0)
    sol = solve(rhs, Interval(lo, hi), (0.0, 0.3), t_eval=[0.1, 0.2, 0.3], adaptive=True, split_ratio=0.001,
                consistency=test)
    assert sol.success and sol.stats["splits"] > 0 and sol.stats["pruned_boxes"] > 0
    sols = trajectories(lambda x: pd.rhs(x), sample_initial_points(lo, hi, 20), 0.3)
    assert misses(sol, sols, per_step=2) == []
