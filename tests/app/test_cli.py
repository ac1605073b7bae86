"""python -m mbs: simulate a scene (result.json + figures), bad scenes, check."""
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from mbs.app.cli import main
from mbs.app.results import read_result, result_boxes
from mbs.app.scene import scene_dir

ROOT = Path(__file__).resolve().parents[2]


SMALL = """
[model]
name = "pendulum_paper"
[initial]
box = [["2.1", "2.2"], ["3.1", "3.2"]]
[simulation]
t_end = 0.3
output_dt = 0.1
mode = "{mode}"
[solver]
subdivision = [2, 2]
[consistency]
test_interval = 0.1
test_splits = 4
"""


@pytest.mark.parametrize("mode", ["i", pytest.param("ii", marks=pytest.mark.slow)])
def test_simulate_writes_result_and_figures(tmp_path, mode, capsys):
    scene = tmp_path / "p.toml"
    scene.write_text(SMALL.format(mode=mode))
    out = tmp_path / "out"
    assert main(["simulate", str(scene), "--out", str(out), "--samples", "8"]) == 0
    data = read_result(out / "result.json")
    assert data["mode"] == mode and data["status"] == "completed" and data["scene"] == str(scene)
    assert [o["t"] for o in data["outputs"]] == [0.0, 0.1, 0.2, 0.3]
    assert data["t_end"] == 0.3 and data["t_reached"] == 0.3
    assert data["stats"]["samples_escaped"] == 0 and data["stats"]["samples_checked"] >= 8
    for k in range(len(data["outputs"])):
        assert np.isfinite(result_boxes(data, k).lo).all()
    assert (out / "enclosures.png").stat().st_size > 1000
    printed = capsys.readouterr().out
    if mode != "i":  # Fig. 3 only where a test pruned a sub-box (else the output says so)
        assert (out / "reduction_area.png").is_file()
        pruned = data["stats"]["pruned_boxes"] > 0
        assert (out / "consistency_plane.png").is_file() == pruned
        assert ("Fig. 3 (consistency_plane.png) not drawn" in printed) == (not pruned)
    assert "all inside" in printed


def test_overrides(tmp_path):
    scene = tmp_path / "p.toml"
    scene.write_text(SMALL.format(mode="ii"))
    out = tmp_path / "o"
    assert main(["simulate", str(scene), "--out", str(out), "--mode", "i", "--t-end", "0.2",
                 "--output-dt", "0.05", "--samples", "0", "--no-figures"]) == 0
    data = json.loads((out / "result.json").read_text())
    assert data["mode"] == "i" and [o["t"] for o in data["outputs"]] == [0.0, 0.05, 0.1, 3 * 0.05, 0.2]
    assert not (out / "enclosures.png").exists()


def _run_cli(*args):
    return subprocess.run([sys.executable, "-m", "mbs", *args], cwd=ROOT, capture_output=True, text=True,
                          timeout=300, env={**os.environ, "PYTHONPATH": str(ROOT)})


@pytest.mark.parametrize("edit,words", [
    (lambda s: s.replace("t_end = 0.3", "t_end = 0.3\nfoo = 2"), ["unknown key", "'foo'"]),
    (lambda s: s.split("[initial]")[0] + "[simulation]" + s.split("[simulation]")[1], ["missing [initial]"]),
    (lambda s: s.replace('["2.1", "2.2"]', '["2.2", "2.1"]'), ["inverted", "box[0]"]),
    (lambda s: s.replace("pendulum_paper", "pendulum_papr"), ["unknown model", "'pendulum_papr'"]),
    (lambda s: s.replace('name = "pendulum_paper"', 'urdf = "missing/robot.urdf"'), ["robot.urdf", "not found"]),
])
def test_bad_scene_is_one_line_exit_2(tmp_path, edit, words, capsys):
    scene = tmp_path / "bad.toml"
    scene.write_text(edit(SMALL.format(mode="i")))
    assert main(["simulate", str(scene), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("error: ") and "\n" not in err and "Traceback" not in err
    for w in words:
        assert w in err
    assert not (tmp_path / "o" / "result.json").exists()


def test_cli_subprocess_errors(tmp_path):
    r = _run_cli("simulate", str(tmp_path / "nope.toml"), "--out", str(tmp_path))
    assert r.returncode == 2 and "Traceback" not in r.stderr and "nope.toml: scene file not found" in r.stderr
    r = _run_cli("simulate", str(scene_dir() / "pendulum_paper.toml"), "--out", str(tmp_path), "--mode", "iv")
    assert r.returncode == 2 and "--mode 'iv'" in r.stderr and "Traceback" not in r.stderr
    r = _run_cli("check", "no_such_robot")
    assert r.returncode == 2 and "unknown model" in r.stderr and "Traceback" not in r.stderr


def test_check_command(capsys):
    assert main(["check", "planar2", "--numeric-only"]) == 0
    out = capsys.readouterr().out
    assert "planar2" in out and "max relative error" in out


# --------------------------------------------------------------------------- issue 14, item 5
@pytest.mark.parametrize("spec", ["panda", "example-robot-data:double_pendulum", "URDF_PATH"])
def test_check_accepts_what_scenes_accept(spec, capsys):
    """check takes robot names users type (panda, not only panda_arm), example-robot-data:NAME
    and URDF paths (it used to accept only models.registry names)."""
    from mbs.robots import urdf_path
    if spec == "URDF_PATH":
        spec = str(urdf_path("double_pendulum"))
    assert main(["check", spec, "--numeric-only"]) == 0
    assert "max relative error" in capsys.readouterr().out


def test_help_lists_every_exit_code(capsys):
    with pytest.raises(SystemExit):
        main(["--help"])
    out = " ".join(capsys.readouterr().out.split())
    for words in ("0 (completed)", "2 (bad input)", "3 (break-down", "4 (stopped by --max-wall)",
                  "130 (interrupted by Ctrl-C)"):
        assert words in out


def test_check_unknown_model_is_one_line(capsys):
    assert main(["check", "pandas"]) == 2
    err = capsys.readouterr().err.strip()
    assert "unknown model 'pandas'" in err and "panda" in err and "\n" not in err
    assert main(["check", "no/such/robot.urdf"]) == 2
    assert "not found" in capsys.readouterr().err


def test_console_script_mbs_is_declared_and_runs_main():
    """pyproject's [project.scripts] mbs = mbs.app.cli:main, installed as an entry point."""
    import importlib.metadata as md
    try:
        import tomllib
    except ModuleNotFoundError:  # Python 3.10
        import tomli as tomllib
    data = tomllib.loads((ROOT / "pyproject.toml").read_text())
    assert data["project"]["scripts"]["mbs"] == "mbs.app.cli:main"
    eps = [e for e in md.entry_points(group="console_scripts") if e.name == "mbs"]
    assert eps and eps[0].load() is main


def test_samples_n_takes_exactly_n(tmp_path):
    scene = tmp_path / "p.toml"
    scene.write_text(SMALL.format(mode="i"))
    for n in (1, 5, 16):  # 16 gave 81 (all corners, 16 random and the centre)
        assert main(["simulate", str(scene), "--out", str(tmp_path / "o"), "--samples", str(n), "--no-figures"]) == 0
        assert read_result(tmp_path / "o" / "result.json")["stats"]["samples_checked"] == n


BREAKS = """
[model]
name = "pendulum_paper"
[initial]
box = [[0.5, 0.6], 0.0]
[simulation]
t_end = 1.0
output_dt = 0.5
mode = "i"
[solver]
max_steps = 3
"""


def test_breakdown_exits_3_and_prints_the_widths_at_the_breakdown(tmp_path, capsys):
    """A break-down is exit code 3; the widths printed are those of the last verified
    step, not of t = 0 (where the point qd(0) = 0 printed as 4.941e-324)."""
    scene = tmp_path / "b.toml"
    scene.write_text(BREAKS)
    assert main(["simulate", str(scene), "--out", str(tmp_path / "o"), "--no-figures", "--samples", "4"]) == 3
    out = capsys.readouterr().out
    data = read_result(tmp_path / "o" / "result.json")
    assert data["status"] == "breakdown" and 0 < data["t_reached"] < 0.5
    line = next(s for s in out.splitlines() if "widths" in s)
    assert "widths at the break-down" in line and "last step" in line and "e-3" not in line
    assert f"{data['t_reached']:g}" in line
    qd_width = float(line.rsplit("qd1 ", 1)[1].split()[0].rstrip(","))
    assert qd_width > 1e-6  # qd has moved away from its point value


def test_max_wall_stops_cleanly_and_writes_result(tmp_path, capsys):
    scene = tmp_path / "p.toml"
    scene.write_text(SMALL.format(mode="ii"))
    out = tmp_path / "o"
    # a limit every run exceeds after its first step (no wall-clock assertion)
    assert main(["simulate", str(scene), "--out", str(out), "--max-wall", "1e-9", "--samples", "3"]) == 4
    data = read_result(out / "result.json")
    assert data["status"] == "stopped" and "wall-clock limit" in data["reason"]
    assert 0 < data["t_reached"] < 0.3 and data["outputs"][0]["t"] == 0.0
    assert "widths when stopped" in capsys.readouterr().out
    assert main(["simulate", str(scene), "--out", str(out), "--max-wall", "0"]) == 2


def test_ctrl_c_stops_cleanly_and_writes_result(tmp_path, monkeypatch, capsys):
    """KeyboardInterrupt during the integration (raised here from the progress
    callback at t >= 0.15) ends with exit 130 and result.json up to then."""
    from mbs import progress

    def interrupting(self, t_now, t_end=None):
        if t_now >= 0.15:
            raise KeyboardInterrupt
    monkeypatch.setattr(progress.Progress, "__call__", interrupting)
    scene = tmp_path / "p.toml"
    scene.write_text(SMALL.format(mode="i"))
    out = tmp_path / "o"
    assert main(["simulate", str(scene), "--out", str(out)]) == 130
    data = read_result(out / "result.json")
    assert data["status"] == "interrupted" and 0.15 <= data["t_reached"] < 0.3
    assert [o["t"] for o in data["outputs"]][:2] == [0.0, 0.1]
    assert np.isfinite(result_boxes(data, 1).lo).all()


# --------------------------------------------------------------------------- [control] (issue 14)
CONTROL = """
[model]
name = "planar2"
[initial]
q1 = [0.499, 0.501]
q2 = [-0.301, -0.299]
qd1 = [-0.001, 0.001]
qd2 = [-0.001, 0.001]
[control]
{control}
[simulation]
t_end = 0.3
output_dt = 0.1
mode = "ii"
[solver]
order = 10
"""


# slow (15 s cold): CI's default step measured 178.2 s of its 3 minutes with it; the
# slow CI step runs it (the controlled scenes' bad-entry checks stay in the default run)
@pytest.mark.slow
def test_controlled_scene_runs_with_frames_and_time_state(tmp_path, capsys):
    scene = tmp_path / "c.toml"
    scene.write_text(CONTROL.format(control='type = "pd"\nkp = [40, 15]\nkd = [12, 4]\ngravity_compensation = true\n'
                                            '[control.trajectory]\nq_end = [0.9, 0.1]\nduration = 1.0\n'
                                            '[control.disturbance]\njoint1 = [-0.1, 0.1]'))
    out = tmp_path / "o"
    assert main(["simulate", str(scene), "--out", str(out), "--samples", "6"]) == 0
    d = read_result(out / "result.json")
    assert d["state_names"] == ["q1", "q2", "qd1", "qd2", "t"]
    assert d["parameters"] == {"disturbance.joint1": [-0.1, 0.1]}
    assert d["control"] == ["pd", "disturbance"]
    assert len(d["frames"]["link2"]["position"]) == len(d["outputs"])
    assert (out / "frame_region.png").exists()
    assert "frame 'link2'" in capsys.readouterr().out


@pytest.mark.parametrize("control, words", [
    ('type = "pd"\nkp = {nope = 1}\nkd = 1', "[control] pd kp: unknown joint 'nope'"),
    ('type = "pd"\nkp = [1, 2, 3]\nkd = 1', "wrong shape (3,)"),
    ('type = "pd"\nkp = [1, nan]\nkd = 1', "NaN"),
    ('type = "lqr"', "unknown controller 'lqr'"),
    ('type = "pd"\nkp = 1\nkd = 1\ngain = 2', "unknown key(s) gain"),
    ('[control.disturbance]\nnope = [0, 1]', "unknown joint 'nope'"),
])
def test_bad_control_is_one_line_exit_2(tmp_path, control, words, capsys):
    scene = tmp_path / "c.toml"
    scene.write_text(CONTROL.format(control=control))
    assert main(["simulate", str(scene), "--out", str(tmp_path / "o"), "--no-figures"]) == 2
    err = capsys.readouterr().err.strip()
    assert words in err and len(err.splitlines()) == 1, err


INVARIANT = CONTROL.replace("t_end = 0.3\noutput_dt = 0.1\nmode = \"ii\"", "t_end = 6.0\noutput_dt = 0.5\nmode = \"i\"") \
    .replace("order = 10\n", "order = 10\ninvariant_after = 0.5\n")


def test_invariant_after_runs_from_a_scene(tmp_path, capsys):
    """A PD hold with `invariant_after`: the run answers to t_end, the runner's own sampled
    trajectories are inside, result.json has every output time."""
    scene = tmp_path / "c.toml"
    scene.write_text(INVARIANT.format(control='type = "pd"\nbandwidth = 4.0\ngravity_compensation = true'))
    out = tmp_path / "o"
    assert main(["simulate", str(scene), "--out", str(out), "--samples", "8", "--no-figures"]) == 0
    d = read_result(out / "result.json")
    assert d["status"] == "completed" and d["t_reached"] == 6.0
    assert [o["t"] for o in d["outputs"]][-1] == 6.0 and len(d["outputs"]) == 13
    printed = capsys.readouterr().out
    assert "all inside" in printed and "every time after 0.5 s proven at once" in printed


def test_invariant_after_with_a_controller_it_cannot_prove_is_one_line_exit_2(tmp_path, capsys):
    scene = tmp_path / "c.toml"
    scene.write_text(INVARIANT.format(control='type = "computed_torque"\nkp = 25\nkd = 10'))
    assert main(["simulate", str(scene), "--out", str(tmp_path / "o"), "--no-figures"]) == 2
    err = capsys.readouterr().err.strip()
    assert "one PD controller" in err and len(err.splitlines()) == 1, err


def test_frame_kernels_compile_in_the_background_only_when_they_help(monkeypatch):
    """The runner starts the affine range's warm-up beside the solver when a robot's frames
    will need those kernels, they are cold and a core is free; not for a bare System, a run
    on several workers, an affine solve (it compiles them itself) or a warm cache."""
    from mbs.app import runner
    from mbs.system import System

    started = []
    monkeypatch.setattr(runner, "start_in_background", lambda fam: started.append(fam) or "proc")
    monkeypatch.setattr(runner, "cold_families", lambda fam: list(fam))
    assert runner._start_frame_warmup("ur5", {}, None) == "proc" and started == [("affine_range",)]
    assert runner._start_frame_warmup("ur5", {}, 1) == "proc"
    assert runner._start_frame_warmup(object.__new__(System), {}, None) is None
    assert runner._start_frame_warmup("ur5", {}, 2) is None
    assert runner._start_frame_warmup("ur5", {"arithmetic": "affine"}, None) is None
    monkeypatch.setattr(runner, "cold_families", lambda fam: [])
    assert runner._start_frame_warmup("ur5", {}, None) is None
    assert len(started) == 2
