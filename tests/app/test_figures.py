"""Figures (mbs.app.figures): Figs. 2, 3, 5 are written; Fig. 3's shaded cells are truly
inconsistent; sampled trajectories agree with an independent integration."""
import numpy as np

from models import pendulum
from mbs.app import figures, sampling
from verified.graph import trace
from verified.arith.interval import Interval

H = trace(lambda x, p: [pendulum.hamiltonian(x)], 2, input_names=["q", "qd"], output_names=["H"])


def test_inconsistent_cells_are_inconsistent():
    cand = Interval([2.9, 0.6], [3.2, 1.5]).subdivide([5, 5]).reshape(-1, 2)
    hv = (19.5, 20.5)
    ei, ej, outside = figures.inconsistent_cells(cand, H, hv, (0, 1), grid=60)
    assert 0 < outside.sum() < outside.size
    rng = np.random.default_rng(0)
    for a, b in zip(*np.nonzero(outside)):
        pts = np.column_stack([rng.uniform(ei[a], ei[a + 1], 20), rng.uniform(ej[b], ej[b + 1], 20)])
        h = H.eval_float(pts)[:, 0]
        assert ((h < hv[0]) | (h > hv[1])).all()
    # and every consistent point lies in an unshaded cell
    pts = np.column_stack([rng.uniform(ei[0], ei[-1], 4000), rng.uniform(ej[0], ej[-1], 4000)])
    h = H.eval_float(pts)[:, 0]
    ok = (h >= hv[0]) & (h <= hv[1])
    a = np.clip(np.searchsorted(ei, pts[:, 0]) - 1, 0, 59)
    b = np.clip(np.searchsorted(ej, pts[:, 1]) - 1, 0, 59)
    assert not outside[a[ok], b[ok]].any()


def test_sampled_trajectories_match_scipy():
    lo, hi = np.array([2.1, 3.1]), np.array([2.2, 3.2])
    pts = sampling.sample_initial_points(lo, hi, 5, corner_limit=10)
    assert pts.shape == (4 + 5 + 1, 2) and (pts >= lo).all() and (pts <= hi).all()
    rhs = trace(pendulum.rhs, 2)
    times = np.linspace(0, 1, 11)
    traj = sampling.sample_trajectories(rhs, pts, times)
    one = sampling.states_at(pendulum.rhs, [pts[3]], times, rtol=1e-12, atol=1e-12)[0]
    assert np.allclose(traj[3], one, atol=1e-9)


def test_paper_figures(tmp_path):
    import mbs.simulate as simulate_module
    x0 = Interval([2.0999999999999996, 3.0999999999999996], [2.2, 3.2])
    sols = simulate_module.compare_modes("pendulum_paper", x0, 0.4, output_dt=0.1, subdivision=[2, 2],
                                         test_interval=0.1, test_splits=4)
    assert set(sols) == {"i", "ii", "iii"}
    times = np.linspace(0, 0.4, 41)
    traj = sampling.sample_trajectories(trace(pendulum.rhs, 2), sampling.sample_initial_points(x0.lo, x0.hi, 6),
                                        times)
    p5 = figures.fig_enclosures(sols, tmp_path / "fig5.png", samples=traj, sample_times=times)
    assert p5.stat().st_size > 5000
    sol = sols["ii"]
    assert sol.consistency is not None and len(sol.consistency.tests) >= 1
    p2 = figures.fig_reduction_area(sol, tmp_path / "fig2.png")
    p3 = figures.fig_consistency_plane(sol, H, tmp_path / "fig3.png", grid=40)
    assert p2.stat().st_size > 5000 and p3.stat().st_size > 5000
    rows = [dict(mode="i", order=8, pieces=4, wall_s=0.5, worst_ratio=3.0),
            dict(mode="ii", order=12, pieces=64, wall_s=2.0, worst_ratio=1.1),
            dict(mode="ii", order=12, pieces=1, wall_s=0.1, worst_ratio=None)]
    assert figures.fig_work_precision(rows, tmp_path / "wp.png").stat().st_size > 5000


def test_fig3_defaults_to_the_test_that_pruned_the_most(tmp_path, monkeypatch):
    """Without test_index, Fig. 3 draws the earliest of the tests that pruned the most
    sub-boxes (the first test of a run usually prunes nothing); an explicit index wins."""
    from types import SimpleNamespace
    cand = Interval([2.9, 0.6], [3.2, 1.5]).subdivide([2, 2]).reshape(-1, 2)

    def rec(t, pruned):
        kept = np.ones(4, bool)
        kept[:pruned] = False
        return SimpleNamespace(t=t, candidates=cand, kept=kept, h_v=Interval(19.5, 20.5))

    sol = SimpleNamespace(consistency=SimpleNamespace(tests=[rec(0.1, 0), rec(0.2, 3), rec(0.3, 1), rec(0.4, 3)]),
                          state_names=["q", "qd"])
    titles = []
    real_save = figures._save

    def save(fig, path):
        titles.append(fig.axes[0].get_title())
        return real_save(fig, path)

    monkeypatch.setattr(figures, "_save", save)
    figures.fig_consistency_plane(sol, H, tmp_path / "a.png", grid=10)
    figures.fig_consistency_plane(sol, H, tmp_path / "b.png", grid=10, test_index=0)
    assert titles[0].startswith("Energy consistency test at t* = 0.2 s")
    assert titles[1].startswith("Energy consistency test at t* = 0.1 s")
