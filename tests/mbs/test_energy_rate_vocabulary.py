"""One vocabulary for dH/dt (verified.consistency.energy_rate): every layer takes energy_rate
with values from one table; old spellings map onto it with a DeprecationWarning
that names the new one; unknown values get a one-line ValueError naming the
allowed ones."""
import warnings

import pytest

from mbs.app.scene import SceneError, loads_scene, scene_dir
from mbs.simulate import simulate, system_for
from mbs.system import System
from verified.consistency.energy_test import EnergyTest
from verified.consistency.energy_rate import DEPRECATED, ENERGY_RATES, MODEL_RATES, SYSTEM_RATES
from verified.graph import trace
from verified.arith.interval import Interval

from models import pendulum as pd


def _graphs():
    rhs = trace(pd.rhs, 2, input_names=["q", "qd"])
    H = trace(lambda x, p: [pd.hamiltonian(x)], 2, input_names=["q", "qd"])
    return rhs, H


def test_the_table_holds_every_value_each_layer_takes():
    assert set(MODEL_RATES) | set(SYSTEM_RATES) == set(ENERGY_RATES)
    assert not set(MODEL_RATES) & set(SYSTEM_RATES)


@pytest.mark.parametrize("old, kw, new", [
    ("System(conservative=True)", dict(conservative=True), "zero"),
    ("System(conservative=False)", dict(conservative=False), "derive"),
    ("System(energy_rate=None)", dict(energy_rate=None), "derive"),
])
def test_old_system_spellings_map_to_energy_rate_and_warn(old, kw, new):
    rhs, H = _graphs()
    with pytest.warns(DeprecationWarning, match=r"use System\(energy_rate=\"" + new):
        s = System("p", rhs, H, **kw)
    assert s.energy_rate == new
    assert old in DEPRECATED


def test_system_conservative_reads_energy_rate_and_warns():
    rhs, H = _graphs()
    s = System("p", rhs, H, energy_rate="zero")
    with pytest.warns(DeprecationWarning, match=r'System.energy_rate == "zero"'):
        assert s.conservative
    with pytest.warns(DeprecationWarning):
        assert not System("p", rhs, H).conservative


def test_conservative_with_a_rate_graph_is_still_refused():
    rhs, H = _graphs()
    with pytest.warns(DeprecationWarning), pytest.raises(ValueError, match="conservative system has no energy_rate"):
        System("p", rhs, H, energy_rate=H, conservative=True)


def test_energy_test_none_maps_to_zero_and_warns():
    _, H = _graphs()
    with pytest.warns(DeprecationWarning, match=r'use EnergyTest\(energy, "zero"\)'):
        test = EnergyTest(H, None)
    assert test.energy_rate == "zero"


def test_the_new_spellings_do_not_warn():
    rhs, H = _graphs()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert System("p", rhs, H).energy_rate == "derive"
        assert System("p", rhs, H, energy_rate="zero").energy_rate == "zero"
        assert System("p", rhs, H, energy_rate=H).energy_rate is H
        for rate in ("derive", "zero", H):
            EnergyTest(H, rate)
        assert system_for("pendulum_paper", "iii", energy_rate="simplified").energy_rate == "zero"


def _one_line(excinfo, *names):
    msg = str(excinfo.value)
    assert "\n" not in msg
    for n in names:
        assert repr(n) in msg
    return msg


def test_unknown_values_name_the_allowed_ones():
    rhs, H = _graphs()
    with pytest.raises(ValueError) as e:
        System("p", rhs, H, energy_rate="simplified")  # a model's choice, not a System's
    assert "or a Graph" in _one_line(e, "derive", "zero")
    with pytest.raises(ValueError) as e:
        EnergyTest(H, "conservative")
    _one_line(e, "derive", "zero")
    with pytest.raises(ValueError) as e:
        simulate("pendulum_paper", Interval([0.1, 0.0], [0.2, 0.1]), 0.1, mode="iii", energy_rate="derive")
    _one_line(e, "unsimplified", "simplified")
    text = (scene_dir() / "pendulum_paper.toml").read_text()
    assert 'energy_rate = "unsimplified"' in text
    loads_scene(text)
    with pytest.raises(SceneError) as e:
        loads_scene(text.replace('energy_rate = "unsimplified"', 'energy_rate = "zero"'))
    msg = str(e.value)
    assert "\n" not in msg and "energy_rate" in msg and "unsimplified, simplified" in msg
