"""mbs.modes: the three modes as one data type, read instead of comparing names."""
import numpy as np
import pytest

from mbs.modes import ALL_MODES, MODE_I, MODE_II, MODE_III, MODES, Mode, get_mode


def test_fields_and_lookup():
    assert MODES == ("i", "ii", "iii") and tuple(m.name for m in ALL_MODES) == MODES
    assert [m.energy_test for m in ALL_MODES] == [False, True, True]
    assert [m.symbolic for m in ALL_MODES] == [False, False, True]
    assert (MODE_II.test_interval, MODE_II.test_splits) == (0.1, 10)          # the paper's settings
    assert (MODE_III.test_interval, MODE_III.test_splits) == (0.01, 50)
    assert get_mode("iii") is MODE_III and get_mode(MODE_I) is MODE_I and str(MODE_II) == "ii"
    assert MODE_I.with_energy_test is MODE_II and MODE_III.with_energy_test is MODE_III
    with pytest.raises(ValueError, match=r"mode must be one of \('i', 'ii', 'iii'\), got 'iv'"):
        get_mode("iv")


def test_defined_once():
    import mbs.robots
    import mbs.simulate
    from mbs.app import figures, scene
    assert scene.MODES is MODES and mbs.simulate.MODES is MODES
    assert scene.PAPER_MODELS is mbs.simulate.PAPER_MODELS is mbs.robots.PAPER_MODELS
    assert mbs.simulate.TEST_DEFAULTS == {"ii": dict(test_interval=0.1, test_splits=10),
                                          "iii": dict(test_interval=0.01, test_splits=50)}
    assert [figures.MODE_STYLE[m.name]["label"] for m in ALL_MODES] == [
        "(i) numeric, no test", "(ii) numeric + energy test", "(iii) symbolic + energy test"]


def test_paper_models_are_registry_system_factories():
    """The paper's models are entries of models.registry.SYSTEMS (System factories),
    named by mbs.robots.PAPER_MODELS; chain names have no System factory."""
    import mbs.robots
    from models.registry import SYSTEMS
    assert tuple(SYSTEMS) == mbs.robots.PAPER_MODELS
    assert mbs.robots.system_entry("pendulum_paper") is SYSTEMS["pendulum_paper"]
    assert mbs.robots.system_entry("ur5") is None and mbs.robots.system_entry(None) is None
    assert SYSTEMS["double_pendulum_paper"].param_names == ["m1", "m2", "l1", "l2", "g"]
    assert SYSTEMS["pendulum_paper"].system(MODE_II, "unsimplified") is None  # the chain's numeric model
    assert SYSTEMS["pendulum_paper"].system(MODE_III, "unsimplified").has_energy


def test_simulate_takes_a_mode_and_records_its_name():
    from mbs.simulate import simulate
    from verified.arith.interval import Interval
    box = Interval([2.1, 3.1], [2.2, 3.2])
    a = simulate("pendulum_paper", box, 0.1, mode=MODE_II, progress=False)
    b = simulate("pendulum_paper", box, 0.1, mode="ii", progress=False)
    assert isinstance(MODE_II, Mode) and a.mode == "ii" == b.mode
    assert bool(np.all(a.hull[-1].equals(b.hull[-1]))) and a.stats["tests"] == b.stats["tests"]


def test_paper_model_names_come_from_the_registries():
    """Issue 15: the names are read from the registries of the entry-point group
    (mbs.robots.registries()), not written down a second time."""
    import mbs.robots
    names = tuple(n for r in mbs.robots.registries() for n in r.SYSTEMS)
    assert mbs.robots.system_names() == names == tuple(mbs.robots.PAPER_MODELS)
    assert "pendulum_paper" in mbs.robots.PAPER_MODELS and "ur5" not in mbs.robots.PAPER_MODELS
