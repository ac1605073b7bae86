"""Bad arguments of verified.solve (issue 12, item 5): each one is refused up front
with a one-line ValueError naming the argument and the bad value.

"Up front" is checked by replacing the Taylor-tape construction and the stepper with
functions that fail the test: the error must come before the ODE is prepared and
before any step (formerly ``tol=0`` or ``h_max=0`` took zero-length steps until
``max_steps``, ``tol=nan`` surfaced as an interval NaN error, ``h_max=nan`` was
ignored and ``subdivision=[4, 4]`` for 4 states leaked a numpy broadcast error).
"""
import numpy as np
import pytest

import verified.driver.batch as batch_mod  # (the one-batch driver: where solve prepares and steps)
from verified.graph import trace
from verified.arith.interval import Interval, empty
from verified.solver import solve

NAN, INF = float("nan"), float("inf")


def _oscillator(n=2):
    if n == 2:
        return trace(lambda x, p: [x[1], -x[0]], 2)
    return trace(lambda x, p: [x[2], x[3], -x[0], -x[1]], 4)


BOX2 = Interval([0.9, -0.1], [1.1, 0.1])
BOX4 = Interval([0.9, -0.1, 0.0, 0.0], [1.1, 0.1, 0.0, 0.0])


@pytest.fixture
def no_work(monkeypatch):
    """Fail the test if solve prepares the ODE or builds a stepper."""
    def prepared(*a, **k):
        raise AssertionError("the ODE was prepared before the arguments were checked")

    def stepped(*a, **k):
        raise AssertionError("integration started before the arguments were checked")

    monkeypatch.setattr(batch_mod, "TaylorODE", prepared)
    monkeypatch.setattr(batch_mod, "_stepper", stepped)


def _refused(match, call, exc=ValueError):
    with pytest.raises(exc, match=match) as info:
        call()
    msg = str(info.value)
    assert "\n" not in msg, msg
    return msg


# (argument named in the message, keyword arguments of solve on the 2-state oscillator)
SETTINGS = [
    ("tol", dict(tol=0.0)),
    ("tol", dict(tol=-1e-10)),
    ("tol", dict(tol=NAN)),
    ("tol", dict(tol=INF)),
    ("tol", dict(tol="1e-10")),
    ("h_max", dict(h_max=0.0)),
    ("h_max", dict(h_max=-0.1)),
    ("h_max", dict(h_max=NAN)),
    ("h_min", dict(h_min=-1e-9)),
    ("h_min", dict(h_min=NAN)),
    ("h_min", dict(h_min=0.0)),        # would let step halving reach a zero-length step
    ("h_min", dict(h_min=0.1, h_max=0.1)),
    ("h_min", dict(h_min=0.5, h_max=0.1)),
    ("order", dict(order=1)),
    ("order", dict(order=0)),
    ("order", dict(order=2.5)),
    ("order", dict(order=True)),
    ("order", dict(order=10**6)),      # (issue 39) accepted before and ran past 120 s
    ("order", dict(order=61)),
    ("max_steps", dict(max_steps=0)),
    ("max_steps", dict(max_steps=-3)),
    ("max_steps", dict(max_steps=10.5)),
    ("max_steps", dict(max_steps=10**12)),
    ("max_boxes", dict(max_boxes=0)),
    ("max_boxes", dict(max_boxes=2**40)),
    ("params_per_state", dict(params_per_state=10**6, set_order=2)),
    ("max_width", dict(max_width=0.0)),
    ("max_width", dict(max_width=NAN)),
    ("t_span", dict(t_span=(1.0, 0.0))),
    ("t_span", dict(t_span=(0.0, 0.0))),
    ("t_span", dict(t_span=(0.0, NAN))),
    ("t_span", dict(t_span=(0.0, INF))),
    ("t_span", dict(t_span=(0.0,))),
    ("t_span", dict(t_span=(0.0, 1.0, 2.0))),
    ("t_eval", dict(t_eval=[0.5, NAN])),
    ("t_eval", dict(t_eval=[INF])),
    ("t_eval", dict(t_eval=[2.0])),
    ("t_eval", dict(t_eval=[-0.5, 1.0])),
    ("t_eval", dict(t_eval=[0.5, 0.25])),
    ("subdivision", dict(subdivision=0)),
    ("subdivision", dict(subdivision=[4, 0])),
    ("subdivision", dict(subdivision=[4, 4, 4])),
    ("subdivision", dict(subdivision=2.5)),
    ("subdivision", dict(subdivision="4")),
    ("subdivision", dict(subdivision=[10**4, 10**4])),  # 10^8 boxes: a MemoryError before
    ("error_basis", dict(error_basis="lu")),
    ("split_ratio", dict(split_ratio=0.0)),
    ("split_ratio", dict(split_ratio=NAN)),
    ("wrap_target", dict(wrap_target=0.0)),
    ("wrap_target", dict(wrap_target=NAN)),
    ("merge_slack", dict(merge_slack=-0.1)),
    ("merge_slack", dict(merge_slack=NAN)),
    ("adaptive", dict(adaptive="yes")),
    ("progress", dict(progress=3)),
    ("model_caps", dict(model_caps={"cubic": 8})),  # needs set_step="composition"
    ("model_caps", dict(model_caps={"quad": 8}, set_order=2, set_step="composition")),
    ("model_caps", dict(model_caps={"cubic": -1}, set_order=2, set_step="composition")),
    ("model_caps", dict(model_caps={"star": True}, set_order=2, set_step="composition")),
    ("model_caps", dict(model_caps=[32, 16], set_order=2, set_step="composition")),
    ("model_caps", dict(model_caps={"pool": -4}, set_order=2, set_step="composition")),
    ("model_caps", dict(model_caps={"pool": 2.5}, set_order=2, set_step="composition")),
    ("model_caps", dict(model_caps={"cubic": 10**4}, set_order=2, set_step="composition")),
]


@pytest.mark.parametrize("name, kwargs", SETTINGS, ids=[f"{n}={list(k.values())}" for n, k in SETTINGS])
def test_bad_setting_is_refused_up_front(no_work, name, kwargs):
    kw = dict(kwargs)
    t_span = kw.pop("t_span", (0.0, 1.0))
    _refused(rf"^{name}\b", lambda: solve(_oscillator(), BOX2, t_span, **kw))


def test_size_limits_are_named_and_the_limit_itself_is_accepted(no_work):
    """A size argument past its bound names the bound (issue 39: ``order=10**6`` hung)."""
    from verified.driver.solver_args import MAX_ORDER
    msg = _refused("order", lambda: solve(_oscillator(), BOX2, (0.0, 1.0), order=MAX_ORDER + 1))
    assert f"[2, {MAX_ORDER}]" in msg and str(MAX_ORDER + 1) in msg
    # the bound itself passes the checks (and reaches the preparation no_work refuses)
    with pytest.raises(AssertionError, match="prepared"):
        solve(_oscillator(), BOX2, (0.0, 1.0), order=MAX_ORDER)


def test_subdivision_of_wrong_length_names_the_expected_length(no_work):
    """The reported case: [4, 4] for a system with 4 states."""
    msg = _refused("subdivision", lambda: solve(_oscillator(4), BOX4, (0.0, 1.0), subdivision=[4, 4]))
    assert "4" in msg and "[4, 4]" in msg and "broadcast" not in msg


def test_h_max_nan_is_not_ignored(no_work):
    _refused(r"h_max .*nan", lambda: solve(_oscillator(), BOX2, (0.0, 1.0), h_max=NAN))


@pytest.mark.parametrize("x0, words", [
    (Interval(np.zeros((0, 2))), "empty batch"),                     # an empty batch of boxes
    (np.array([NAN, 0.0]), "NaN"),
    (Interval([0.0, 0.0, 0.0]), "2 components"),
    (empty((2,)), "empty"),                                          # an empty interval [inf, -inf]
    (Interval([-INF, 0.0], [0.0, 0.0], allow_unbounded=True), "bounded"),
    ([BOX2, Interval([0.0, 0.0, 0.0])], "2 components"),
    # (lo, hi) as initial_box() returns it: was taken as two point states, silently
    ((np.array([0.0, 1.0]), np.array([0.1, 1.1])), "Interval(lo, hi)"),
    ([[0.0, 1.0], [0.1, 1.1]], "two point states"),
])
def test_bad_initial_boxes(no_work, x0, words):
    msg = _refused("^x0", lambda: solve(_oscillator(), x0, (0.0, 1.0)))
    assert words in msg, msg


def test_two_equal_points_or_an_array_of_points_are_still_taken():
    """The refusal is only for a pair of different vectors in a tuple or list: a (2, n)
    array stays two point states."""
    sol = solve(_oscillator(), np.array([[0.0, 1.0], [0.1, 1.1]]), (0.0, 0.01))
    assert sol.boxes[0].shape == (2, 2) and np.all(sol.boxes[0].width() < 1e-300)  # (width() rounds up)


def test_zero_dimensional_system(no_work):
    g = trace(lambda x, p: [], 0)
    _refused("no states", lambda: solve(g, Interval(np.zeros(0)), (0.0, 1.0)))


@pytest.mark.parametrize("params, words", [
    (None, "pass params"),
    ([0.5, 0.7], r"shape \(1,\)"),
    (Interval([[0.5], [0.6], [0.7]]), "one row per initial box"),
    (np.array([NAN]), "params"),
])
def test_bad_params(no_work, params, words):
    g = trace(lambda x, p: [-p[0] * x[0]], 1, 1)
    _refused(words, lambda: solve(g, Interval([1.0], [2.0]), (0.0, 1.0), params=params))


def test_params_for_an_ode_without_parameters(no_work):
    _refused("no parameters", lambda: solve(_oscillator(), BOX2, (0.0, 1.0), params=[1.0]))


def test_simulate_passes_the_solver_error_through(no_work):
    """mbs.simulate gives the same one-line error (it does not repeat the checks)."""
    from mbs.simulate import simulate
    box = Interval([2.1, 3.1], [2.2, 3.2])
    _refused("^tol must be", lambda: simulate("pendulum_paper", box, 1.0, mode="i", tol=0.0))
    _refused("^subdivision", lambda: simulate("pendulum_paper", box, 1.0, mode="i", subdivision=[4, 4, 4]))
    _refused("^h_max", lambda: simulate("pendulum_paper", box, 1.0, mode="i", h_max=NAN))


def test_scene_runner_reports_the_solver_error(no_work, tmp_path):
    """Settings each valid on their own but refused together reach the user of a
    scene as a one-line SceneError carrying the solver's message."""
    from mbs.app.runner import run_scene
    from mbs.app.scene import SceneError, load_scene, scene_dir
    text = (scene_dir() / "pendulum_paper.toml").read_text()
    text = text.replace("[solver]\n", "[solver]\nh_min = 0.5\nh_max = 0.1\n").replace('mode = "ii"', 'mode = "i"')
    assert "h_min = 0.5" in text
    path = tmp_path / "bad.toml"
    path.write_text(text)
    scene = load_scene(path)
    msg = _refused("h_min must be smaller than h_max", lambda: run_scene(scene, tmp_path / "out", figures=False,
                                                                         samples=0, progress=False), SceneError)
    assert "bad.toml" in msg


def test_good_arguments_still_accepted():
    """The checks accept what the solver accepts: numpy scalars, h_max = inf, a
    per-state subdivision given as a numpy array, repeated output times."""
    sol = solve(_oscillator(), BOX2, (np.float64(0.0), np.float64(0.5)), t_eval=[0.25, 0.25, 0.5],
                order=np.int64(8), tol=np.float64(1e-8), h_max=INF, subdivision=np.array([2, 1]),
                max_steps=np.int64(1000))
    assert sol.success and list(sol.t) == [0.0, 0.25, 0.5] and sol.stats["boxes"] == 2


def test_model_caps_reach_the_composition_stepper(monkeypatch):
    """solve(model_caps=...) sets the stepper's monomial caps; keys left out keep the defaults."""
    from verified.steppers import tm_flow
    seen = {}
    real = tm_flow.TaylorModelFlowStepper.__init__

    def record(self, *a, **k):
        real(self, *a, **k)
        seen.update(quadratic=self.quadratic_cap, cubic=self.cubic_cap, star=self.star_cap, pool=self.pool_cap)

    monkeypatch.setattr(tm_flow.TaylorModelFlowStepper, "__init__", record)
    sol = solve(_oscillator(), BOX2, (0.0, 0.1), set_order=2, set_step="composition", arithmetic="taylor_model",
                model_caps={"quadratic": 5, "cubic": 3})
    assert sol.status == "completed"
    assert seen == dict(quadratic=5, cubic=3, star=tm_flow.STAR_CAP, pool=tm_flow.TaylorModelFlowStepper.POOL)
    sol = solve(_oscillator(), BOX2, (0.0, 0.1), set_order=2, set_step="composition", arithmetic="taylor_model",
                model_caps={"pool": 0})
    assert sol.status == "completed" and seen["pool"] == 0


# (issue 39, item 4) numpy RuntimeWarnings must not leak to the user: a setting or a box
# at the edge of the floats is a result or an error in words
_METHODS = [dict(), dict(set_order=2), dict(set_order=2, set_step="composition"), dict(arithmetic="affine"),
            dict(arithmetic="taylor_model"), dict(error_basis="auto")]


@pytest.mark.parametrize("kw", _METHODS, ids=lambda kw: ",".join(f"{k}={v}" for k, v in kw.items()) or "default")
def test_huge_tol_completes_without_a_runtime_warning(kw):
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # before the fix: "overflow encountered in divide" (lohner.suggest_step)
        sol = solve(_oscillator(), BOX2, (0.0, 1.0), tol=1e300, **kw)
    assert sol.status == "completed"


@pytest.mark.parametrize("big", [1e150, 1e300, 1.7e308])
@pytest.mark.parametrize("max_width", [1e3, INF])
def test_huge_box_breaks_down_in_words_without_a_runtime_warning(big, max_width):
    import warnings
    g = trace(lambda x, p: [x[1], -x[0] - 2 * x[1] * x[0] * x[0]], 2)
    # (dict(): the default, method="auto"; the QR-Lohner method, the default before, named)
    for kw in _METHODS + [dict(method="lohner")]:
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            sol = solve(g, Interval([-big, -big], [big, big]), (0.0, 1.0), max_width=max_width, **kw)
        assert sol.status == "breakdown" and sol.t_reached == 0.0, (kw, sol.status)
        assert any(w in sol.reason for w in ("overflow", "too wide", "unbounded")), (kw, sol.reason)
