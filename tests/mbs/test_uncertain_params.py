"""Uncertain physical parameters (issue 14, item 2): payloads, mass scales, body masses,
joint damping and DH/paper symbols enter the graphs as PARAMs; verified enclosures
contain Pinocchio ``aba`` + DOP853 trajectories for sampled parameters and states."""
import itertools
import math

import numpy as np
import pinocchio as pin
import pytest

from oracles.sampling import misses, pinocchio_with, trajectories
from mbs.app.scene import SceneError, loads_scene
from mbs.simulate import simulate, system_for
from mbs.uncertain import ChainParameters, ParameterError
from models import double_pendulum as dp
from models.registry import get
from verified.arith.interval import Interval


# --------------------------------------------------------------------------- oracle
def aba_trajectory(model, damping, x0, times):
    """States at ``times`` of qdd = aba(q, qd, -D qd) (DOP853, rtol = atol = 1e-12)."""
    data = model.createData()
    n = model.nv
    d = np.asarray(damping, float)
    q0 = pin.neutral(model)

    def f(x):  # continuous joints have nq = 2 (cos, sin): q = integrate(neutral, angles)
        return np.r_[x[n:], pin.aba(model, data, pin.integrate(model, q0, x[:n]), x[n:], -d * x[n:])]
    return trajectories(f, [x0], times[-1])[0]


def corners_and_random(lo, hi, n_random, seed=0):
    rng = np.random.default_rng(seed)
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    pts = [lo, hi, (lo + hi) / 2]
    pts += list(lo + rng.uniform(0, 1, (n_random, lo.size)) * (hi - lo))
    return pts


# --------------------------------------------------------------------------- regressions
def test_paper_model_parameter_interval_from_python_runs_and_is_sound():
    """simulate(params=...) used to die (AttributeError / 'the ODE has no parameters')."""
    lo, hi = dp.initial_box()
    lo[0], hi[0] = 2.3, 2.31
    sol = simulate("double_pendulum_paper", Interval(lo, hi), 0.2, mode="i", output_dt=0.1,
                   params={"m1": [0.9, 1.1]})
    assert sol.status == "completed", sol.reason
    assert sol.params == {"m1": (0.9, 1.1)}
    trajs = []
    for i, m1 in enumerate([0.9, 1.1, 1.0]):
        trajs += trajectories(lambda x: dp.rhs(x, m1=m1), corners_and_random(lo, hi, 3, seed=i), 0.2)
    assert not misses(sol, trajs, per_step=3)
    # the mass really is a parameter: the enclosure is wider than with m1 = 1 fixed
    fixed = simulate("double_pendulum_paper", Interval(lo, hi), 0.2, mode="i", output_dt=0.1)
    assert (sol.hull[-1].width() > 1.5 * fixed.hull[-1].width()).any()


def test_paper_model_parameter_interval_in_mode_iii():
    lo, hi = dp.initial_box()
    sol = simulate("double_pendulum_paper", Interval(lo, hi), 0.2, mode="iii", params={"m2": [0.95, 1.05]},
                   subdivision=[4, 1, 1, 1], test_interval=0.1)
    assert sol.status == "completed", sol.reason
    trajs = [s for m2 in (0.95, 1.05)
             for s in trajectories(lambda x, m2=m2: dp.rhs(x, m2=m2), corners_and_random(lo, hi, 2), 0.2)]
    assert not misses(sol, trajs, per_step=3)


SCENE_M1 = """
[model]
name = "double_pendulum_paper"
[parameters]
m1 = [0.9, 1.1]
[initial]
x1 = [2.3, 2.31]
x2 = "-11*pi/20"
x3 = 0.43
x4 = 0.67
[simulation]
t_end = 0.2
output_dt = 0.1
mode = "ii"
"""


def test_scene_with_parameter_interval_runs(tmp_path):
    """[parameters] m1 = [0.9, 1.1] used to crash (AttributeError: 'dict' object has no
    attribute 'width'); now it runs, samples the parameter and writes it out."""
    from mbs.app.results import read_result
    from mbs.app.runner import run_scene
    rep = run_scene(loads_scene(SCENE_M1), tmp_path, samples=12, figures=False)
    sol = rep["solution"]
    assert sol.status == "completed", sol.reason
    assert rep["checked"] == 12 and rep["escaped"] == 0
    lo, hi = read_result(tmp_path / "result.json")["parameters"]["m1"]
    assert lo <= 0.9 <= 1.1 <= hi and lo < 0.9  # 0.9 is enclosed, not rounded
    assert rep["system"].rhs.param_names == ("m1",)


def test_dh_scene_with_uncertain_length_and_mass():
    scene = loads_scene("""
[model]
dh = [ {joint = "R", a = "l1", mass = "m1"}, {joint = "R", a = 1.0, mass = 1.0} ]
gravity = [9.81, 0.0, 0.0]
[parameters]
l1 = [0.99, 1.01]
m1 = 1.5
[initial]
box = [[0.5, 0.51], 0.2, 0.0, 0.0]
[simulation]
t_end = 0.2
mode = "i"
""")
    kw = scene.simulate_kwargs()
    assert set(kw["params"]) == {"l1"}  # the point mass is substituted, the interval is a PARAM
    model = scene.build_model()
    sol = simulate(model, scene.initial_box(["q1", "q2", "qd1", "qd2"]), 0.2, **kw)
    assert sol.status == "completed", sol.reason
    trajs = []
    for l1 in (0.99, 1.01):  # the oracle: the paper's hand-written eq. (22)
        trajs += trajectories(lambda x, l1=l1: dp.rhs(x, m1=1.5, l1=l1),
                              corners_and_random([0.5, 0.2, 0, 0], [0.51, 0.2, 0, 0], 2), 0.2)
    assert not misses(sol, trajs, per_step=3)


# --------------------------------------------------------------------------- graphs
def test_physical_parameters_are_graph_params_and_match_pinocchio():
    """Float evaluation of the parametrized graphs = Pinocchio aba / kinetic energy on a
    model whose inertias carry the sampled payload and scale (UR5, payload on tool0)."""
    chain = get("ur5")
    spec = {"payload": {"link": "tool0", "mass": [0.9, 1.1], "com": [0.0, [0.01, 0.03], [0.04, 0.06]]},
            "mass_scale": [0.95, 1.05], "damping": {"elbow_joint": [0.0, 0.2]}}
    system = system_for(chain, "ii", params=spec)
    assert system.rhs.param_names == ("payload.mass", "payload.com_y", "payload.com_z", "mass_scale",
                                      "damping.elbow_joint")
    assert system.energy.param_names == system.rhs.param_names
    rng = np.random.default_rng(3)
    n = chain.n
    outs = []
    for _ in range(4):
        q, qd = rng.uniform(-2, 2, n), rng.uniform(-1, 1, n)
        pv = np.array([rng.uniform(0.9, 1.1), rng.uniform(0.01, 0.03), rng.uniform(0.04, 0.06),
                       rng.uniform(0.95, 1.05), rng.uniform(0, 0.2)])
        model = pinocchio_with(chain, [("tool0", pv[0], [0.0, pv[1], pv[2]])], scale=pv[3])
        data = model.createData()
        d = np.zeros(n)
        d[2] = pv[4]
        ref = pin.aba(model, data, q, qd, -d * qd)
        got = system.rhs.eval_float(np.r_[q, qd], pv)[n:]
        assert np.allclose(got, ref, rtol=1e-8, atol=1e-8)
        # K + P against Pinocchio (its P leaves out the fixed base: compare differences)
        q2 = rng.uniform(-2, 2, n)
        H = [system.energy.eval_float(np.r_[a, qd], pv)[0] for a in (q, q2)]
        K = [pin.computeKineticEnergy(model, data, a, qd) for a in (q, q2)]
        P = [pin.computePotentialEnergy(model, data, a) for a in (q, q2)]
        assert math.isclose(H[0] - H[1], (K[0] + P[0]) - (K[1] + P[1]), rel_tol=1e-9, abs_tol=1e-9)
        outs.append(got)
    # not baked in: other parameter values give other accelerations
    x = np.r_[np.zeros(n), np.ones(n)]
    a = system.rhs.eval_float(x, [0.9, 0.01, 0.04, 1.0, 0.0])
    b = system.rhs.eval_float(x, [1.1, 0.03, 0.06, 1.0, 0.2])
    assert np.abs(a - b).max() > 1e-3


def test_interval_graph_evaluation_encloses_sampled_parameters():
    chain = get("double_pendulum_paper_urdf")
    cp = ChainParameters(chain, {"payload": {"link": "link2", "mass": [0.2, 0.3], "com": [0, 0, [-0.12, -0.08]]},
                                 "mass": {"link1": [0.9, 1.1]}, "damping": [0.0, 0.05]})
    g = cp.rhs_graph()
    x = Interval([0.3, 0.2, 0.1, -0.1])
    enc = g.eval_interval(x, cp.interval())
    rng = np.random.default_rng(0)
    for pv in rng.uniform(cp.lo, cp.hi, (50, cp.n)):
        assert enc.contains(g.eval_float(x.mid(), pv)).all()


# --------------------------------------------------------------------------- soundness
@pytest.mark.parametrize("mode", ["i", "ii"])
def test_payload_scale_damping_enclosures_contain_pinocchio_trajectories(mode):
    """The paper's double pendulum from its URDF with a payload (mass and centre of mass
    uncertain) on link2, all masses scaled by [0.97, 1.03] and damping in [0, 0.05]:
    every corner of the parameter box x the initial box's corners, Pinocchio aba +
    DOP853, inside; affine arithmetic keeps the width within 3x the sampled spread
    (measured 1.7-1.9x; plain intervals: 7-20x)."""
    chain = get("double_pendulum_paper_urdf")
    spec = {"payload": {"link": "link2", "mass": [0.2, 0.3], "com": [0.0, 0.0, [-0.12, -0.08]]},
            "mass_scale": [0.97, 1.03], "damping": [0.0, 0.05]}
    lo, hi = np.array([2.0, 0.5, 0.0, 0.0]), np.array([2.01, 0.5, 0.0, 0.0])
    sol = simulate(chain, Interval(lo, hi), 0.2, mode=mode, output_dt=0.05, params=spec, test_interval=0.05,
                   arithmetic="affine", order=10)
    assert sol.status == "completed", sol.reason
    assert sol.params["payload.mass"] == (0.2, 0.3)
    plo = np.array([0.2, -0.12, 0.97, 0.0, 0.0])
    phi = np.array([0.3, -0.08, 1.03, 0.05, 0.05])
    trajs = []
    for corner in itertools.product(*zip(plo, phi)):
        pv = np.array(corner)
        model = pinocchio_with(chain, [("link2", pv[0], [0, 0, pv[1]])], scale=pv[2])
        for x0 in (lo, hi):
            trajs.append(aba_trajectory(model, pv[3:], x0, [0.2]))
    rng = np.random.default_rng(7)
    for k, pv in enumerate(rng.uniform(plo, phi, (3, 5))):
        model = pinocchio_with(chain, [("link2", pv[0], [0, 0, pv[1]])], scale=pv[2])
        trajs.append(aba_trajectory(model, pv[3:], lo + rng.uniform(0, 1, 4) * (hi - lo), [0.2]))
    assert not misses(sol, trajs, per_step=2)
    spread = np.ptp([tr(0.2) for tr in trajs], axis=0)
    assert (sol.hull[-1].width() < 3 * spread + 1e-9).all(), sol.hull[-1].width() / spread


# (3-4 s: behind the slow marker to keep the default run under 3 minutes)
@pytest.mark.slow
def test_ur5_payload_on_tool0_is_sound():
    """UR5, payload 1 kg +- 10% on tool0 (affine arithmetic), q(0) +- 1e-3: Pinocchio
    trajectories with sampled payloads stay inside."""
    chain = get("ur5")
    q0 = np.array([0.3, -1.2, 1.0, -0.5, 0.4, 0.1])
    lo, hi = np.r_[q0 - 1e-3, np.zeros(6)], np.r_[q0 + 1e-3, np.zeros(6)]
    sol = simulate(chain, Interval(lo, hi), 0.08, mode="i", output_dt=0.04, order=8, arithmetic="affine",
                   params={"payload": {"link": "tool0", "mass": [0.9, 1.1]}})
    assert sol.status == "completed", sol.reason
    trajs = []
    for k, m in enumerate([0.9, 1.1, 1.0]):
        model = pinocchio_with(chain, [("tool0", m, [0, 0, 0])])
        for x0 in corners_and_random(lo, hi, 1, seed=k):
            trajs.append(aba_trajectory(model, np.zeros(6), x0, [0.08]))
    assert not misses(sol, trajs, per_step=2)


def test_shared_mass_scale_is_factored_out_exactly():
    """qdd does not depend on a mass scale shared by all bodies without damping or
    payload, and the interval enclosure over the scale stays as tight as at a point."""
    chain = get("double_pendulum_paper_urdf")
    g = ChainParameters(chain, {"mass_scale": [0.5, 2.0]}).rhs_graph()
    x = Interval([0.3, 0.2, 0.1, -0.1])
    wide = g.eval_interval(x, Interval([0.5], [2.0]))
    point = chain.numeric().rhs_graph().eval_interval(x)
    assert np.allclose(wide.width(), point.width(), atol=1e-12)


# --------------------------------------------------------------------------- bad input
@pytest.mark.parametrize("spec, match", [
    ({"payload": {"link": "nope", "mass": 1.0}}, r"unknown link 'nope'"),
    ({"payload": {"link": "tool0", "mass": [1.1, 0.9]}}, r"payload mass: inverted interval"),
    ({"payload": {"link": "tool0", "mass": float("nan")}}, r"payload mass: NaN"),
    ({"payload": {"link": "tool0", "mass": [1.0, 2.0], "com": [0, 0]}}, r"payload com: expected 3 entries"),
    ({"payload": {"link": "tool0", "mass": [1.0, 2.0, 3.0]}}, r"an interval is \[lo, hi\]"),
    ({"payload": {"link": "tool0", "mass": -1.0}}, r"payload mass: must be >= 0"),
    ({"payload": {"link": "tool0", "mas": 1.0}}, r"unknown key"),
    ({"payload": {"link": "base_link", "mass": 1.0}}, r"fixed base"),
    ({"mass_scale": [0.0, 1.0]}, r"mass_scale: must be > 0"),
    ({"mass_scale": {"tool0": [0.9, 1.1]}}, r"welded to body 'wrist_3_link'"),
    ({"mass": {"nobody": [1, 2]}}, r"unknown body 'nobody'"),
    ({"damping": {"knee": [0, 1]}}, r"unknown joint 'knee'"),
    ({"damping": [-1.0, 1.0]}, r"damping: must be >= 0"),
    ({"damping": [0.0, float("inf")]}, r"not finite"),
    ({"m1": [0.9, 1.1]}, r"unknown parameter 'm1' for model 'ur5'"),
])
def test_bad_parameters_get_one_line_errors(spec, match):
    box = Interval(np.zeros(12), np.zeros(12))
    with pytest.raises(ParameterError, match=match) as e:
        simulate("ur5", box, 0.1, mode="i", params=spec)
    assert "\n" not in str(e.value)


def test_bad_params_type_and_mode_iii():
    box = Interval(np.zeros(4), np.zeros(4))
    with pytest.raises(ValueError, match="must be a dict"):
        simulate("double_pendulum_paper_urdf", box, 0.1, params=[1.0])
    with pytest.raises(ValueError, match="modes i and ii"):
        simulate("double_pendulum_paper_urdf", box, 0.1, mode="iii", params={"damping": [0, 1]})
    with pytest.raises(ValueError, match="mode iii takes only the paper's parameters"):
        simulate("double_pendulum_paper", box, 0.1, mode="iii", params={"damping": [0, 1]})


@pytest.mark.parametrize("table, match", [
    ('[parameters.payload]\nlink = "link2"\nmass = [1.1, 0.9]', r"\[parameters\] payload mass: inverted"),
    ('[parameters.payload]\nlink = "link2"\nmass = 1.0\ncom = [0, 0]', r"payload com: expected \[x, y, z\]"),
    ('[parameters.payload]\nmass = 1.0', r"payload: missing 'link'"),
    ('[parameters]\nm1 = [0.9, 1.1]', r"unknown parameter 'm1'"),
    ('[parameters]\ndamping = "nan"', r"damping"),
    ('[parameters]\nmass_scale = [0.0, 1.0]', r"mass_scale: must be > 0"),
])
def test_bad_scene_parameters(table, match):
    text = f"""
[model]
urdf = "example-robot-data:double_pendulum"
{table}
[initial]
box = [0.1, 0.0, 0.0, 0.0]
[simulation]
t_end = 0.1
"""
    with pytest.raises(SceneError, match=match):
        loads_scene(text)


def test_scene_unknown_payload_link_exits_2(tmp_path, capsys):
    from mbs.app.cli import main
    p = tmp_path / "s.toml"
    p.write_text("""
[model]
urdf = "example-robot-data:double_pendulum"
[parameters.payload]
link = "tool0"
mass = [0.9, 1.1]
[initial]
box = [0.1, 0.0, 0.0, 0.0]
[simulation]
t_end = 0.1
""")
    assert main(["simulate", str(p), "--out", str(tmp_path / "o"), "--no-figures"]) == 2
    err = capsys.readouterr().err.strip()
    assert "[parameters] payload: unknown link 'tool0'; links of" in err and "\n" not in err


def test_system_parameters_by_name():
    """A System's graph parameters by name (a dict used to reach solve() and fail)."""
    from mbs.system import System
    from verified.graph import trace
    g = trace(lambda x, p: [x[1], -p[0] * np.sin(x[0])], 2, 1, input_names=["q", "qd"], param_names=["k"])
    system = System("pendulum_k", g)
    box = Interval([0.5, 0.0], [0.51, 0.0])
    sol = simulate(system, box, 0.3, mode="i", output_dt=0.1, params={"k": [9.0, 10.0]})
    assert sol.status == "completed", sol.reason
    assert sol.params == {"k": (9.0, 10.0)}
    trajs = [s for k in (9.0, 9.5, 10.0)
             for s in trajectories(lambda x, k=k: [x[1], -k * np.sin(x[0])], ([0.5, 0], [0.51, 0]), 0.3)]
    assert not misses(sol, trajs, per_step=3)
    with pytest.raises(ValueError, match=r"unknown parameter\(s\) 'g' for 'pendulum_k'; its parameters: k"):
        simulate(system, box, 0.1, mode="i", params={"g": 9.81})
    with pytest.raises(ValueError, match=r"params k: inverted interval"):
        simulate(system, box, 0.1, mode="i", params={"k": [10.0, 9.0]})
    with pytest.raises(ValueError, match="pass params"):
        simulate(system, box, 0.1, mode="i")


@pytest.mark.slow  # default-run budget (CI's cold default step measured 170-183 s of 180 at 1e891d1/1caded6)
def test_shipped_payload_scene_runs_from_the_cli(tmp_path, capsys):
    """models/scenes/double_pendulum_payload.toml (to 0.1 s here; its full 0.5 s run is
    in the slow test of every shipped scene): parameters sampled, figures with them."""
    from mbs.app.cli import main
    from mbs.app.results import read_result
    assert main(["simulate", "double_pendulum_payload", "--out", str(tmp_path), "--t-end", "0.1",
                 "--samples", "8"]) == 0
    data = read_result(tmp_path / "result.json")
    assert data["status"] == "completed" and data["stats"]["samples_checked"] == 8
    assert set(data["parameters"]) == {"mass_scale", "damping.joint1", "damping.joint2", "payload.mass",
                                       "payload.com_z"}
    assert (tmp_path / "enclosures.png").is_file() and (tmp_path / "reduction_area.png").is_file()
    # (Fig. 3 only where a test pruned a sub-box)
    assert (tmp_path / "consistency_plane.png").is_file() == (data["stats"]["pruned_boxes"] > 0)
    assert "uncertain parameters: mass_scale in [0.97, 1.03]" in capsys.readouterr().out
