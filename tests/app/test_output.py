"""Output a person can read (issue 41 item 5): the compile note and the progress bar's
phases and clock (mbs.progress), the tightness table of ``mbs simulate`` (result.json
"tightness"), Fig. 5's widths and Fig. 3 only where something was pruned
(mbs.app.figures), the note on a bare URDF's default frame (mbs.frames)."""
import io
import json
import time
from types import SimpleNamespace

import numpy as np
import pytest

from mbs import progress
from mbs.app import figures, runner
from mbs.app.cli import main
from mbs.app.results import format_tightness, read_result, tightness

PENDULUM = """
[model]
name = "pendulum_paper"
[initial]
box = [["2.1", "2.2"], ["3.1", "3.2"]]
[simulation]
t_end = 0.2
output_dt = 0.1
mode = "{mode}"
[solver]
subdivision = [1, 1]
[consistency]
test_interval = 0.1
test_splits = 2
"""

URDF = """
[model]
urdf = "example-robot-data:double_pendulum"
[initial]
q1 = [2.399, 2.401]
q2 = 0.0
qd1 = 0.0
qd2 = 0.0
[simulation]
t_end = 0.05
output_dt = 0.05
mode = "i"
{frames}
"""


def _scene(text, tmp_path, name="s.toml"):
    path = tmp_path / name
    path.write_text(text)
    return path


# ----------------------------------------------------------------- (a) compile note, bar
def test_compile_note_only_when_the_cache_is_cold():
    cold = lambda module: (1, 10)  # noqa: E731 - stubs of numba's on-disk cache
    warm = lambda module: (9, 10)  # noqa: E731
    note = progress.compile_note(("interval",), probe=cold)
    assert note.startswith("compiling interval kernels (first run only, about ") and note.endswith(" s) ...")
    assert progress.compile_note(("interval",), probe=warm) == ""
    assert progress.compile_note(("interval",), probe=lambda m: None) == ""  # cannot tell: silent
    both = progress.compile_note(("interval", "affine"), " for the frame enclosures",
                                 probe=lambda m: (0, 4) if "affine" in m else (4, 4))
    assert both.startswith("compiling affine kernels for the frame enclosures (first run only")
    s = sum(progress.KERNEL_FAMILIES[f][1] for f in ("interval", "Taylor-model"))
    assert f"about {s} s" in progress.compile_note(("interval", "Taylor-model"), probe=cold)


def test_kernel_cache_probe_reads_numba_index_files():
    state = progress.kernel_cache_warm("verified.arith._kernels")
    assert state is not None and 0 <= state[0] <= state[1] and state[1] > 10
    assert progress.kernel_cache_warm("verified.no_such_module") is None


def test_bar_clock_counts_from_the_start_and_names_the_phase():
    f = io.StringIO()
    bar = progress.Progress(1.0, "mode ii", enabled=True, file=f, start=time.time() - 65)
    bar.phase("compiling", then="solving")
    bar(0.25, 1.0)  # the first step: compiled
    bar.phase("sampling 8 trajectories")
    bar.note("a note")
    bar.close()
    text = f.getvalue()
    assert "mode ii: compiling" in text and "mode ii: solving" in text and "sampling 8 trajectories" in text
    assert "[01:05<" in text  # the clock counts from start, not from the bar's creation
    assert "a note\n" in text
    quiet = io.StringIO()
    bar = progress.Progress(1.0, enabled=False, file=quiet, start=time.time() - 65)
    bar.phase("compiling")
    bar(0.5, 1.0)
    bar.note("a note")
    bar.close()
    assert quiet.getvalue() == "" and bar._thread is None


def test_runner_says_when_kernels_compile(tmp_path, monkeypatch, capsys):
    """With the kernel cache cold (stubbed), a run on a terminal (forced) prints the note
    and the phases on stderr; on a pipe (the tests' stderr) it prints nothing there."""
    from mbs.app.scene import load_scene
    scene = load_scene(_scene(PENDULUM.format(mode="i"), tmp_path))
    monkeypatch.setattr(progress, "kernel_cache_warm", lambda module: (0, 10))
    runner.run_scene(scene, tmp_path / "quiet", samples=2, figures=False)
    assert capsys.readouterr().err == ""
    f = io.StringIO()
    real = runner.Progress
    monkeypatch.setattr(runner, "Progress", lambda *a, **k: real(*a, **{**k, "enabled": True, "file": f,
                                                                       "start": time.time() - 3}))
    runner.run_scene(scene, tmp_path / "tty", samples=2, figures=False)
    text = f.getvalue()
    assert "compiling interval and Taylor-model kernels (first run only, about" in text
    assert "mode i: compiling" in text and "mode i: sampling 2 trajectories" in text
    # numba's cache unreadable: no note, the phase says what may be happening
    monkeypatch.setattr(progress, "kernel_cache_warm", lambda module: None)
    f.seek(0)
    f.truncate()
    runner.run_scene(scene, tmp_path / "tty", samples=2, figures=False)
    text = f.getvalue()
    assert "kernels (first run only" not in text and "mode i: first step (compiling, on a first run)" in text


def test_kernel_families_follow_the_method():
    assert runner.kernel_families({}) == ("interval", "Taylor-model")  # auto: the composition first
    assert runner.kernel_families({"order": 12, "tol": 1e-10}) == ("interval",)  # the old signature: lohner
    assert runner.kernel_families({"method": "lohner"}) == ("interval",)
    assert runner.kernel_families({"order": 12, "arithmetic": "affine"}) == ("interval", "affine")


# ----------------------------------------------------------------- (b) tightness table
def test_summary_table_gives_width_spread_ratio_and_method(tmp_path, capsys):
    out = tmp_path / "o"
    assert main(["simulate", str(_scene(PENDULUM.format(mode="i"), tmp_path)), "--out", str(out),
                 "--samples", "6", "--no-figures"]) == 0
    printed = capsys.readouterr().out
    data = read_result(out / "result.json")
    tight = json.loads((out / "result.json").read_text())["tightness"]
    assert tight["t"] == data["t_end"] == 0.2 and tight["samples"] == 6
    assert tight["method"] == data["method"] and tight["method"]
    hull = np.array(data["outputs"][-1]["hull"])
    assert [r["name"] for r in tight["states"]] == data["state_names"]
    for r, (lo, hi) in zip(tight["states"], hull):
        assert r["ratio"] == r["width"] / r["spread"]
        assert 0 < r["spread"] <= r["width"] and r["width"] == pytest.approx(hi - lo, rel=1e-12)
    worst = max(tight["states"], key=lambda r: r["ratio"])
    assert tight["worst"] == {"name": worst["name"], "ratio": worst["ratio"]}
    table = printed[printed.index(f"at t = 0.2 s (method: {tight['method']}), against 6 sampled trajectories:"):]
    assert all(w in table.splitlines()[1].split() for w in ("state", "width", "spread", "ratio"))
    assert f"worst ratio: {worst['ratio']:.3f} ({worst['name']})" in table


def test_tightness_of_point_states_and_without_samples():
    sol = SimpleNamespace(t=np.array([0.0, 1.0]), method="lohner", state_names=["q", "qd", "t"],
                          hull=SimpleNamespace(width=lambda: np.array([[0.1, 0.2, 0.0], [0.3, 0.4, 0.0]])))
    s = tightness(sol, np.array([0.15, 0.4, 0.0]), samples=5)
    assert [r["ratio"] for r in s["states"]] == [0.3 / 0.15, 1.0, None] and s["worst"]["name"] == "q"
    text = format_tightness(s)
    assert text.splitlines()[-1].startswith("worst ratio: 2.000 (q)") and "  t " in text
    none = tightness(sol, None)
    assert none["worst"] is None and all(r["spread"] is None for r in none["states"])
    assert "no sampled trajectories" in format_tightness(none)


# ----------------------------------------------------------------- (c) Figs. 3 and 5
def test_fig3_only_when_something_was_pruned(tmp_path, capsys):
    out = tmp_path / "o"
    assert main(["simulate", str(_scene(PENDULUM.format(mode="ii"), tmp_path)), "--out", str(out),
                 "--samples", "2"]) == 0
    printed = capsys.readouterr().out
    data = read_result(out / "result.json")
    assert data["stats"]["tests"] >= 1 and data["stats"]["pruned_boxes"] == 0
    assert not (out / "consistency_plane.png").exists()
    assert "nothing pruned by the" in printed and "Fig. 3 (consistency_plane.png) not drawn" in printed
    assert (out / "enclosures.png").is_file() and (out / "reduction_area.png").is_file()


def test_pruned_anything():
    rec = lambda *kept: SimpleNamespace(kept=np.array(kept, bool))  # noqa: E731
    assert not runner.pruned_anything(SimpleNamespace(consistency=None))
    assert not runner.pruned_anything(SimpleNamespace(consistency=SimpleNamespace(tests=[rec(1, 1)])))
    assert runner.pruned_anything(SimpleNamespace(consistency=SimpleNamespace(tests=[rec(1, 1), rec(1, 0)])))


def test_fig5_shows_widths_and_excess_per_mode_on_log_scales(tmp_path, monkeypatch):
    """Per state: the enclosure, its width (log) with the samples' spread under every
    mode's width, and the excess width / spread - 1 (log), one line per mode."""
    from mbs.app.sampling import sample_trajectories
    from mbs.simulate import simulate, system_for
    from verified.arith.interval import Interval
    x0 = Interval([2.1, 3.1], [2.2, 3.2])
    sols = {m: simulate("pendulum_paper", x0, 0.2, mode=m, output_dt=0.1, progress=False, test_interval=0.1,
                        test_splits=2) for m in ("i", "ii")}
    times = np.linspace(0, 0.2, 21)
    traj = sample_trajectories(system_for("pendulum_paper", "i").rhs,
                               np.array([[2.1, 3.1], [2.2, 3.2], [2.1, 3.2], [2.15, 3.15]]), times)
    seen = []
    real_save = figures._save
    monkeypatch.setattr(figures, "_save", lambda fig, path: (seen.append(fig), real_save(fig, path))[1])
    figures.fig_enclosures(sols, tmp_path / "fig5.png", samples=traj, sample_times=times)
    fig = seen[0]
    axes = np.array(fig.axes).reshape(2, 3)  # one row per state: enclosure | width | excess
    for k in range(2):
        axw, axr = axes[k, 1], axes[k, 2]
        assert axw.get_yscale() == "log" and axr.get_yscale() == "log"
        spread = [ln for ln in axw.lines if ln.get_label().startswith("sampled spread")]
        assert len(spread) == 1
        sp = np.asarray(spread[0].get_ydata())
        assert np.allclose(spread[0].get_xdata(), [0.0, 0.1, 0.2])  # at the output times
        for mode, sol in sols.items():
            (w_line,) = [ln for ln in axw.lines if ln.get_label().startswith(f"({mode})")]
            (r_line,) = [ln for ln in axr.lines if ln.get_label().startswith(f"({mode})")]
            w = np.asarray(sol.hull.width(), float)[:, k]
            assert np.allclose(w_line.get_ydata(), w) and (w >= sp * (1 - 1e-9)).all()
            assert np.allclose(r_line.get_ydata(), np.maximum(w / sp - 1, figures.EXCESS_FLOOR))
    assert "black" not in fig._suptitle.get_text()
    # without samples: enclosure | width
    seen.clear()
    figures.fig_enclosures(sols, tmp_path / "fig5b.png")
    assert len(seen[0].axes) == 4 and seen[0].axes[1].get_yscale() == "log"


# ----------------------------------------------------------------- (d) a bare URDF's frame
def test_bare_urdf_default_frame_is_said(tmp_path, capsys):
    from mbs.frames import default_frame_note
    from mbs.robots import load_model
    note = default_frame_note(load_model("example-robot-data:double_pendulum"))
    assert note.startswith("frame: no tool frame given; using the origin of joint 'joint2' (the last joint")
    assert default_frame_note(load_model("ur5")) == ""  # tool0: a tool frame
    out = tmp_path / "o"
    assert main(["simulate", str(_scene(URDF.format(frames=""), tmp_path)), "--out", str(out), "--samples", "2",
                 "--no-figures"]) == 0
    printed = capsys.readouterr().out
    assert note in printed and "frame 'link2'" in printed
    # a frame named in the scene: nothing to say
    assert main(["simulate", str(_scene(URDF.format(frames='frames = ["link2"]'), tmp_path, "named.toml")),
                 "--out", str(out), "--samples", "2", "--no-figures"]) == 0
    assert "no tool frame given" not in capsys.readouterr().out
