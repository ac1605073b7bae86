"""Scene files (mbs.app.scene): parsing, rigorous enclosure of numbers, clear errors."""
import math
from fractions import Fraction

import numpy as np
import pytest

from mbs.app.scene import SceneError, enclose_number, load_scene, loads_scene, output_times, scene_dir
from verified.arith.exact import ExpressionError, enclose_pi_multiple, parse_pi_expression

GOOD = """
name = "t"
[model]
name = "double_pendulum_paper"
[initial]
x1 = ["0.99*3*pi/4", "1.01*3*pi/4"]
x2 = "-11*pi/20"
x3 = 0.43
x4 = "67/100"
[simulation]
t_end = 1.0
output_dt = 0.1
mode = "i"
[solver]
order = 12
subdivision = { x1 = 8 }
[consistency]
test_splits = 10
"""

NAMES = ["x1", "x2", "x3", "x4"]


def test_shipped_scenes_load():
    for name in ("pendulum_paper", "double_pendulum_paper", "double_pendulum_urdf"):
        s = load_scene(scene_dir() / f"{name}.toml")
        assert s.t_end > 0 and s.mode in ("i", "ii", "iii")
        s.build_model()
    # a shipped scene by name
    assert load_scene("double_pendulum_paper").name.startswith("double pendulum")


def test_paper_box_matches_model():
    from models import double_pendulum as dp
    s = loads_scene(GOOD)
    box = s.initial_box(NAMES)
    lo, hi = dp.initial_box()
    assert np.array_equal(box.lo, lo) and np.array_equal(box.hi, hi)
    assert s.subdivision_for(NAMES) == [8, 1, 1, 1]
    kw = s.simulate_kwargs(NAMES)
    assert kw["subdivision"] == [8, 1, 1, 1] and kw["mode"] == "i" and kw["test_splits"] == 10


def test_number_enclosures_are_rigorous():
    # decimals that are not doubles: the tightest enclosing pair, one ulp wide
    for lit in ("0.43", "0.1", "2.1", "1e-300", "123456.789"):
        lo, hi = enclose_number(float(lit))
        q = Fraction(lit)
        assert Fraction(lo) < q < Fraction(hi) and math.nextafter(lo, math.inf) == hi
        assert enclose_number(lit) == (lo, hi)
    # exact doubles and integers stay points
    assert enclose_number(2.5) == (2.5, 2.5) and enclose_number(3) == (3.0, 3.0)
    assert enclose_number("1/4") == (0.25, 0.25)
    # pi expressions: verified.arith.exact.parse_pi_expression, then enclose_pi_multiple (their
    # tests, against 60-digit mpmath: tests/verified/test_exact_expressions.py)
    assert enclose_number("-11*pi/20") == enclose_pi_multiple(0, Fraction(-11, 20))


@pytest.mark.parametrize("text", ["pi*pi", "1/pi", "1/0", "sin(1)", "2**3", "import os", "x1", "1 +"])
def test_bad_expressions(text):
    # the parser's message (verified.arith.exact.ExpressionError) after the scene key
    with pytest.raises(ExpressionError) as parsed:
        parse_pi_expression(text)
    with pytest.raises(SceneError) as e:
        enclose_number(text, "[initial] x1")
    assert str(e.value) == f"[initial] x1: {parsed.value}"


@pytest.mark.parametrize("value", ["1e400", "-1e400*pi", 10**400, -(10**400)])
def test_numbers_beyond_a_double_are_one_line_errors(value):
    with pytest.raises(SceneError, match=r"^\[initial\] x1: .* is too large for a double"):
        enclose_number(value, "[initial] x1")


def test_output_times_are_multiples():
    assert output_times(1.0, 0.25) == [0.25, 0.5, 0.75, 1.0]
    assert output_times(1.0, 0.3) == [0.3, 0.6, 0.8999999999999999, 1.0]
    assert output_times(0.5, None) == [0.5]
    ts = output_times(3.0, 0.05)
    assert len(ts) == 60 and ts[-1] == 3.0 and all(t == (k + 1) * 0.05 for k, t in enumerate(ts[:-1]))


def _err(text, *words, names=None):
    with pytest.raises(SceneError) as e:
        s = loads_scene(text)
        s.build_model()
        s.initial_box(names or NAMES)
        s.simulate_kwargs(names or NAMES)
    msg = str(e.value)
    assert "\n" not in msg
    for w in words:
        assert w in msg, msg
    return msg


def test_bad_scenes_name_the_problem(tmp_path):
    _err(GOOD.replace("mode = \"i\"", "mode = \"i\"\nfoo = 1"), "[simulation]", "'foo'")
    _err(GOOD.replace("[consistency]", "[consistency]\ntest_split = 3"), "[consistency]", "'test_split'")
    _err(GOOD + "\n[extra]\na = 1\n", "'extra'")
    _err(GOOD.replace('x3 = 0.43', 'x3 = [0.5, 0.43]'), "[initial] x3", "inverted")
    _err(GOOD.replace('x3 = 0.43', 'x3 = nan'), "[initial] x3", "not a finite")
    _err(GOOD.replace('x3 = 0.43', 'x3 = inf'), "[initial] x3", "not a finite")
    _err(GOOD.replace('x3 = 0.43\n', ''), "missing initial value", "'x3'")
    _err(GOOD.replace('x3 = 0.43\n', 'x9 = 0.43\n'), "unknown state", "'x9'")
    text = GOOD.split("[initial]")[0] + GOOD.split('x4 = "67/100"')[1]
    _err(text, "missing [initial]")
    _err(GOOD.replace("double_pendulum_paper", "triple_pendulum"), "unknown model", "'triple_pendulum'")
    # what `check` takes as a name belongs in urdf = in a scene: the error says so
    _err(GOOD.replace("double_pendulum_paper", "example-robot-data:ur5"), "unknown model",
         "urdf = 'example-robot-data:ur5'")
    _err(GOOD.replace('name = "double_pendulum_paper"', 'urdf = "nope.urdf"'), "nope.urdf", "not found")
    bad = tmp_path / "bad.urdf"
    bad.write_text("<robot name='x'><link name='a'/><joint name='j' type='revolute'>")
    _err(GOOD.replace('name = "double_pendulum_paper"', f'urdf = "{bad}"'), "bad.urdf")
    _err(GOOD.replace("t_end = 1.0", "t_end = -1.0"), "t_end", "> 0")
    _err(GOOD.replace("t_end = 1.0\n", ""), "missing t_end")
    _err(GOOD.replace('mode = "i"', 'mode = "iv"'), "mode", "'iv'")
    _err(GOOD.replace("order = 12", "order = 12.5"), "[solver] order", "integer")
    _err(GOOD.replace("{ x1 = 8 }", "[8, 1]"), "subdivision", "2 entries")
    _err(GOOD.replace("{ x1 = 8 }", "{ y = 8 }"), "subdivision", "'y'")
    _err("[model\nname=1", "not valid TOML")


def test_bad_scene_file(tmp_path):
    with pytest.raises(SceneError, match="not found"):
        load_scene(tmp_path / "missing.toml")
    p = tmp_path / "s.toml"
    p.write_text(GOOD.replace("[initial]", "[initial]\n").replace('x2 = "-11*pi/20"', 'x2 = "-11*pi/"'))
    with pytest.raises(SceneError, match=r"s\.toml: \[initial\] x2: cannot parse"):
        load_scene(p)


def test_urdf_relative_path_and_dh_parameters(tmp_path):
    from models import double_pendulum as dp
    (tmp_path / "robots").mkdir()
    (tmp_path / "robots" / "dp.urdf").write_text(dp.urdf_xml())
    text = """
[model]
urdf = "robots/dp.urdf"
lock = {}
[initial]
box = [[2.3, 2.4], 0.1, 0, 0]
[simulation]
t_end = 0.5
"""
    p = tmp_path / "scene.toml"
    p.write_text(text)
    s = load_scene(p)
    chain = s.build_model()
    assert chain.n == 2
    assert s.initial_box(["q1", "q2", "qd1", "qd2"]).shape == (4,)
    dh = """
[model]
dh = [ {joint = "R", a = "l1", mass = "m1"}, {joint = "R", a = 1.0, mass = 1.0} ]
gravity = [9.81, 0.0, 0.0]
[parameters]
l1 = 1.0
m1 = 2.0
[initial]
box = [[2.3, 2.4], 0.1, 0, 0]
[simulation]
t_end = 0.5
"""
    s = loads_scene(dh)
    c = s.build_model()
    assert not c.free_symbols and c.n == 2
    assert "params" not in s.simulate_kwargs()
    _err(dh.replace('a = "l1"', 'a = "l7"'), "'l7'", "names no parameter")
    # interval parameters are handed to simulate
    s = loads_scene(dh.replace("m1 = 2.0", "m1 = [1.9, 2.1]"))
    assert s.simulate_kwargs()["params"] == {"m1": (1.9, 2.1)}


def test_scene_model_names_users_type():
    """[model] name accepts the aliases of mbs.robots (panda -> panda_arm), like check."""
    from mbs.robots import load_model
    from mbs.app.scene import loads_scene
    scene = loads_scene('[model]\nname = "panda"\n[initial]\nbox = ' + str([0.0] * 14) + '\n[simulation]\nt_end = 0.1\n')
    assert scene.build_model() == "panda"
    assert load_model("panda").n == 7 and load_model("panda").joint_names == load_model("panda_arm").joint_names
    with pytest.raises(SceneError, match="unknown model 'pandas'"):
        loads_scene('[model]\nname = "pandas"\n[initial]\nbox = [0.0]\n[simulation]\nt_end = 0.1\n')


def test_solver_set_order_and_merge_slack():
    text = GOOD.replace("order = 12\n", "order = 12\nset_order = 2\nmerge_slack = 0.1\n")
    kw = loads_scene(text).simulate_kwargs(NAMES)
    assert kw["set_order"] == 2 and kw["merge_slack"] == 0.1
    _err(GOOD.replace("order = 12\n", "order = 12\nset_order = 3\n"), "set_order", "must be 1 or 2")


def test_solver_set_step():
    text = GOOD.replace("order = 12\n", 'order = 12\nset_order = 2\nset_step = "composition"\n')
    kw = loads_scene(text).simulate_kwargs(NAMES)
    assert kw["set_step"] == "composition" and kw["set_order"] == 2
    _err(GOOD.replace("order = 12\n", 'order = 12\nset_step = "taylor"\n'), "set_step",
         "must be 'mean_value' or 'composition'")
    kw = loads_scene(text.replace("set_order = 2\n", "set_order = 2\nmodel_degree = 2\n")).simulate_kwargs(NAMES)
    assert kw["model_degree"] == 2
    _err(text.replace("set_order = 2\n", "set_order = 2\nmodel_degree = 5\n"), "model_degree", "must be 2, 3 or 4")


def test_solver_energy_shell_and_params_per_state():
    kw = loads_scene(GOOD.replace("order = 12\n", "order = 12\nenergy_shell = true\nparams_per_state = 12\n")
                     ).simulate_kwargs(NAMES)
    assert kw["energy_shell"] is True and kw["params_per_state"] == 12
    _err(GOOD.replace("order = 12\n", "order = 12\nenergy_shell = 1\n"), "energy_shell")
    _err(GOOD.replace("order = 12\n", "order = 12\nparams_per_state = 0\n"), "params_per_state")


def test_solver_arithmetic():
    for name in ("interval", "affine", "taylor_model"):
        kw = loads_scene(GOOD.replace("order = 12\n", f"order = 12\narithmetic = '{name}'\n")).simulate_kwargs(NAMES)
        assert kw["arithmetic"] == name
    _err(GOOD.replace("order = 12\n", "order = 12\narithmetic = 'taylor'\n"), "arithmetic", "'taylor_model'")


def test_solver_invariant_after():
    kw = loads_scene(GOOD.replace("order = 12\n", "order = 12\ninvariant_after = 0.5\n")).simulate_kwargs(NAMES)
    assert kw["invariant_after"] == 0.5
    _err(GOOD.replace("order = 12\n", "order = 12\ninvariant_after = 'soon'\n"), "invariant_after")


def test_control_scenes_parse():
    """[control] tables are kept for simulate; structure errors name the file and key."""
    from mbs.control import parse_control
    for name in ("arm2_computed_torque", "ur5_pd_payload", "ur5_quintic", "panda_pd_hold"):
        s = load_scene(name)
        assert s.control is not None and parse_control(s.control)
        assert s.simulate_kwargs()["control"] == s.control
    base = "[model]\nname = 'planar2'\n[initial]\nbox = [0, 0, 0, 0]\n[simulation]\nt_end = 1\n"
    with pytest.raises(SceneError, match="control.*unknown controller"):
        loads_scene(base + "[control]\ntype = 'x'\n")
    with pytest.raises(SceneError, match="mode i or ii"):
        loads_scene(base.replace("t_end = 1", "t_end = 1\nmode = 'iii'") + "[control]\ntype = 'pd'\nkp = 1\nkd = 1\n")
    with pytest.raises(SceneError, match="frames"):
        loads_scene(base.replace("t_end = 1", "t_end = 1\nframes = 3"))


def test_solver_method_and_its_fields_validated_by_the_method():
    """(issue 40) ``[solver] method = "..."`` plus that method's own fields become one
    method object; a field the method does not have, or a bad value, is a one-line error."""
    from verified.methods import Auto, Composition
    kw = loads_scene(GOOD.replace("order = 12\n", 'method = "composition"\norder = 8\nmodel_degree = 4\n')
                     ).simulate_kwargs(NAMES)
    assert kw["method"] == Composition(order=8, model_degree=4)
    assert "order" not in kw and "model_degree" not in kw and kw["subdivision"] == [8, 1, 1, 1]
    kw = loads_scene(GOOD.replace("order = 12\n", 'method = "auto"\ntarget_ratio = 1.02\n')).simulate_kwargs(NAMES)
    assert kw["method"] == Auto(target_ratio=1.02)
    _err(GOOD.replace("order = 12\n", 'method = "lohner"\nmodel_degree = 3\n'), "model_degree",
         "not a setting of method 'lohner'")
    _err(GOOD.replace("order = 12\n", 'method = "composition"\norder = 99\n'), "composition: order")
    _err(GOOD.replace("order = 12\n", 'method = "rk45"\n'), "method", "'rk45'")
