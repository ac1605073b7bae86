"""The README's main job and the shipped scenes reach their own end time.

``python -m mbs demo`` runs the paper's double pendulum in modes i, ii, iii with
:func:`mbs.app.demo.settings`; every shipped scene (``models/scenes/*.toml``) runs in its own
mode. A break-down before the end time fails (status "completed" and
``t_reached == t_end``), and so does a sampled trajectory outside a scene's enclosure.
Slow (about 15-50 s each here): ``python -m pytest -m slow``.
"""
import pytest

from mbs.app import demo
from mbs.app.runner import run_scene
from mbs.app.scene import load_scene, scene_dir
from mbs.simulate import MODES, simulate

SCENES = sorted(p.stem for p in scene_dir().glob("*.toml"))


def _assert_reaches(sol, t_end, what):
    assert sol.status == "completed" and sol.t_reached == t_end, (
        f"{what}: {sol.status} at t = {sol.t_reached} of {t_end} ({sol.reason})")


def test_there_are_shipped_scenes():
    assert {"pendulum_paper", "double_pendulum_paper", "double_pendulum_urdf"} <= set(SCENES)


@pytest.mark.slow
@pytest.mark.parametrize("mode", MODES)
def test_demo_configuration_reaches_its_end_time(mode):
    x0, kw = demo.settings()
    t_end = demo.DEMO["t_end"]
    sol = simulate("double_pendulum_paper", x0, t_end, mode=mode, output_dt=demo.DEMO["output_dt"], **kw)
    _assert_reaches(sol, t_end, f"demo, mode {mode}")


@pytest.mark.slow
@pytest.mark.parametrize("name", SCENES)
def test_shipped_scene_reaches_its_end_time(name, tmp_path):
    scene = load_scene(name)
    report = run_scene(scene, tmp_path, samples=16, figures=False, progress=False)
    _assert_reaches(report["solution"], scene.t_end, f"scene {name} (mode {scene.mode})")
    assert report["checked"] >= 16 and report["escaped"] == 0


@pytest.mark.slow
def test_the_swinging_pendulum_tests_at_a_maximum_of_ra(tmp_path):
    """Fig. 2 as the paper draws it: RA(t) rises to a first local maximum and the test
    runs there (not because test_interval passed)."""
    import numpy as np
    report = run_scene(load_scene("pendulum_swinging"), tmp_path, samples=8, figures=False, progress=False)
    rec = report["solution"].consistency
    first = rec.tests[0]
    assert first.trigger == "RA maximum" and first.t < 1.0
    # a local maximum of the recorded RA at or just before t* (one step after it when
    # the step cannot be rolled back)
    k = int(np.argmin(np.abs(rec.ra_t - first.t)))
    ra = rec.ra
    peaks = [j for j in range(1, k + 1) if ra[j] > 0 and ra[j] >= ra[j - 1] and ra[j] > ra[j + 1]]
    assert peaks and k - peaks[0] <= 1
