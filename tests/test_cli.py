"""python -m mbs: simulate a scene (result.json + figures), bad scenes, check."""
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from mbs.__main__ import main
from mbs.results import read_result, result_boxes
from mbs.scene import scene_dir

ROOT = Path(__file__).resolve().parents[1]


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


@pytest.mark.parametrize("mode", ["i", "ii"])
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
    if mode != "i":
        assert (out / "reduction_area.png").is_file() and (out / "consistency_plane.png").is_file()
    assert "all inside" in capsys.readouterr().out


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
