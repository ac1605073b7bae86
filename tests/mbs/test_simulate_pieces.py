"""Per-piece break-downs of a robot run (issue 39, item 3): ``simulate`` over several
initial boxes of a 2-link planar arm, one of them so wide that its accelerations are
unbounded at t = 0 (the LDL^T pivots of M(q) over it contain 0), the others narrow:
before, the whole run broke down at t = 0; now the wide piece breaks down alone, the
run reports which, and the narrow pieces go on (their enclosures hold sampled true
trajectories, scipy's DOP853 at rtol 1e-12). ``python -m mbs simulate`` prints and
writes the same (result.json's "pieces" and "surviving")."""
import numpy as np
import pytest
from mbs.app.sampling import dop853

from mbs.app.cli import main
from mbs.app.results import read_result
from mbs.app.runner import status_line
from mbs.simulate import simulate, system_for
from verified.arith.interval import Interval

T = 0.3
CENTRES = np.array([[0.3, -0.4, 0, 0], [0.2, -0.3, 0, 0], [0.5, 0.1, 0, 0], [0.3, 0.0, 0, 0]], float)


def _boxes(wide=1.0, narrow=5e-4):
    r = np.full_like(CENTRES, narrow)
    r[1, :2] = wide  # piece 1: q +- 1 rad
    return Interval(CENTRES - r, CENTRES + r)


def _escapes(sol, rhs, boxes, count=4, seed=0):
    """(sample, output) of true states outside ``sol``'s boxes, from the centre and
    ``count`` random points of each of ``boxes`` (scipy DOP853, rtol = atol = 1e-12)."""
    rng = np.random.default_rng(seed)
    times = np.asarray(sol.t, float)
    pts = []
    for lo, hi in zip(np.asarray(boxes.lo, float), np.asarray(boxes.hi, float)):
        pts += [0.5 * (lo + hi)] + [lo + rng.uniform(0, 1, lo.size) * (hi - lo) for _ in range(count)]
    bad = []
    for s, x0 in enumerate(pts):
        traj = dop853(lambda t, x: rhs.eval_float(x[None, :])[0], x0, times[-1], dense=False, t_eval=times)
        for k, x in enumerate(traj.y.T):
            lo, hi = np.asarray(sol.boxes[k].lo, float), np.asarray(sol.boxes[k].hi, float)
            tol = 1e-9 * (1 + np.abs(x))
            if not ((lo - tol <= x) & (x <= hi + tol)).all(axis=1).any():
                bad.append((s, k))
    return bad


@pytest.mark.parametrize("mode", ["i", "ii"])
def test_a_wide_piece_breaks_down_alone(mode):
    x0 = _boxes()
    sol = simulate("planar2", x0, T, mode=mode, output_dt=T / 3, progress=False, workers=1,
                   order=12, tol=1e-10)  # (the QR-Lohner method named: the driver's own run)
    assert sol.status == "breakdown" and sol.t_reached == 0.0 and list(sol.t) == [0.0]
    assert sol.failed_pieces == [1]
    p = sol.piece_results[1]
    assert p.t_reached == 0.0 and "Taylor coefficients are unbounded" in p.reason
    assert np.array_equal(p.box.lo, x0.lo[1]) and np.array_equal(p.box.hi, x0.hi[1])
    assert [q.status for q in sol.piece_results] == ["completed", "breakdown", "completed", "completed"]
    assert sol.reason.startswith("1 of 4 pieces failed (piece 1 at t = 0: Taylor coefficients are unbounded")
    assert sol.reason.endswith("3 pieces verified to t = 0.3")
    assert status_line(sol).startswith("breakdown at t = 0 s: 1 of 4 pieces failed (piece 1 at t = 0: ")
    s = sol.surviving
    assert s.status == "completed" and s.t_reached == T and len(s.t) == 4 and s.mode == mode
    assert s.state_names == sol.state_names == ("q1", "q2", "qd1", "qd2")
    assert all(b.shape[0] == 3 for b in s.boxes)
    assert np.isfinite(s.hull.lo).all() and (s.boxes[-1].width() < 0.02).all()  # (measured <= 0.0094)
    rhs = system_for("planar2", "i").rhs
    alive = Interval(np.asarray(x0.lo)[[0, 2, 3]], np.asarray(x0.hi)[[0, 2, 3]])
    assert _escapes(s, rhs, alive) == []


CLI_SCENE = """
[model]
name = "planar2"
[initial]
q1 = [0.299, 0.301]
q2 = [-3.0, 3.0]
qd1 = 0.0
qd2 = 0.0
[simulation]
t_end = 0.02
output_dt = 0.01
mode = "i"
[solver]
subdivision = { q2 = 8 }
order = 12
tol = 1e-10
"""


@pytest.mark.slow  # (~5-8 s: the default run stays under 3 minutes)
def test_cli_prints_and_writes_the_pieces(tmp_path, capsys):
    """8 pieces of q2 in [-3, 3]: the pieces about the stretched arm break down within a
    few ms (measured: 5, at 1.4 ms), the others run to the end; exit code 3 (a
    break-down), the line names the pieces, result.json carries both parts, and the
    sampled trajectories of the surviving pieces are inside their enclosure."""
    scene = tmp_path / "arm.toml"
    scene.write_text(CLI_SCENE)
    out = tmp_path / "o"
    assert main(["simulate", str(scene), "--out", str(out), "--no-figures", "--samples", "8"]) == 3
    text = capsys.readouterr().out
    data = read_result(out / "result.json")
    failed = [p["index"] for p in data["pieces"]["failed"]]
    assert data["status"] == "breakdown" and data["pieces"]["count"] == 8 and 0 < len(failed) < 8
    assert data["t_reached"] == min(p["t_reached"] for p in data["pieces"]["failed"]) < 0.02
    surv = data["surviving"]
    assert surv["status"] == "completed" and surv["t_reached"] == 0.02
    assert sorted(surv["pieces"] + failed) == list(range(8))
    assert [o["t"] for o in surv["outputs"]] == [0.0, 0.01, 0.02]
    assert len(surv["outputs"][-1]["boxes"]) >= len(surv["pieces"])
    assert all(lo <= hi for o in surv["outputs"] for b in o["boxes"] for lo, hi in b)
    assert data["reason"] == data["pieces"]["summary"]
    assert data["reason"].startswith(f"{len(failed)} of 8 pieces failed (")
    line = next(s for s in text.splitlines() if s.startswith("breakdown at t = "))
    assert f": {len(failed)} of 8 pieces failed (" in line and f"{8 - len(failed)} pieces verified to t = 0.02" in line
    assert f"the {8 - len(failed)} surviving pieces: completed at t = 0.02 s" in text
    assert "sampled trajectories from the surviving pieces: all inside" in text
    assert data["stats"]["surviving_samples_checked"] == 8 and data["stats"]["samples_escaped"] == 0
