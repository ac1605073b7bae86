"""``python -m mbs demo``: what the library can prove today, on the paper's examples.

Until the verified ODE solver lands (issue #4), the demo shows the pieces it is built
from, each against an independent check:

1. The pendulum of paper sec. 5.1: its Hamiltonian (eq. 19) traced into an expression
   graph and enclosed over the initial box [2.1, 2.2] x [3.1, 3.2], without and with
   subdivision (all pieces in one batched call), against dense float sampling.
2. The paper's double pendulum (eq. 22): the right-hand side enclosed over the initial
   box (25), once from the hand-written equations and once from the SMARTMOBILE-style
   numeric model of a DH chain traced into a graph, against sampled float values.
3. The same double pendulum's mass matrix over a box of angles: a verified solve of
   M(q) qdd = b (preconditioned interval Gauss elimination) against sampled solves.
4. The verified ODE solver on that double pendulum to T = 1 (initial box split into
   256 pieces), against the hull of 401 densely sampled DOP853 trajectories.
"""

from __future__ import annotations

import time

import numpy as np

from verified.graph import trace
from verified.interval import Interval
from verified.linalg import solve


def _table(rows, header):
    widths = [max(len(str(r[i])) for r in rows + [header]) for i in range(len(header))]
    line = "  ".join(h.ljust(w) for h, w in zip(header, widths))
    out = [line, "-" * len(line)]
    out += ["  ".join(str(c).ljust(w) for c, w in zip(r, widths)) for r in rows]
    return "\n".join(out)


def _grid(lo, hi, per_axis):
    axes = [np.linspace(a, b, per_axis) for a, b in zip(lo, hi)]
    return np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, len(lo))


def pendulum_energy(pieces=(1, 4, 16, 64)):
    """Rows of (pieces, enclosure of H, width, width / sampled width, ms)."""
    from models import pendulum

    graph = trace(pendulum.hamiltonian, 2, input_names=["q", "qd"], output_names=["H"])
    lo, hi = pendulum.initial_box()
    box = Interval(lo, hi)
    sampled = graph.eval_float(_grid(lo, hi, 401))[:, 0]
    true_w = sampled.max() - sampled.min()
    graph.eval_interval(box)  # warm up: the first call loads the compiled kernels
    rows = []
    for n in pieces:
        t0 = time.perf_counter()
        parts = box.subdivide(n)  # n x n boxes, evaluated in one batched call
        h = graph.eval_interval(parts)[..., 0]
        enc = Interval(h.lo.min(), h.hi.max())
        ms = (time.perf_counter() - t0) * 1e3
        assert enc.lo <= sampled.min() and sampled.max() <= enc.hi, "enclosure misses a sample"
        w = float(enc.width())
        rows.append((f"{n}x{n}", f"[{float(enc.lo):.6f}, {float(enc.hi):.6f}]", f"{w:.5f}", f"{w / true_w:.3f}", f"{ms:.1f}"))
    rows.append(("sampled", f"[{sampled.min():.6f}, {sampled.max():.6f}]", f"{true_w:.5f}", "1.000", ""))
    return rows


def double_pendulum_rhs():
    """Rows comparing the eq. (22) graph and the traced DH numeric model over box (25)."""
    from models import double_pendulum as dp

    lo, hi = dp.initial_box()
    box = Interval(lo, hi)
    by_hand = trace(dp.rhs, 4, output_names=["x1d", "x2d", "x3d", "x4d"])
    numeric = dp.dh_chain().numeric()
    by_chain = trace(lambda x, p: _chain_rhs(numeric, x), 4)
    # x1 is the only uncertain component; sample it densely (and the corners).
    pts = np.repeat(lo[None, :], 2001, axis=0)
    pts[:, 0] = np.linspace(lo[0], hi[0], 2001)
    samples = by_hand.eval_float(pts)
    rows = []
    for name, g in (("eq. (22) by hand", by_hand), ("DH chain, numeric model", by_chain)):
        enc = g.eval_interval(box)
        assert enc.contains(samples).all(), f"{name}: enclosure misses a sample"
        for i in (2, 3):
            rows.append((name, f"x{i + 1}'", f"[{enc.lo[i]:.6f}, {enc.hi[i]:.6f}]", f"{enc.width()[i]:.2e}"))
    for i in (2, 3):
        rows.append(("sampled", f"x{i + 1}'", f"[{samples[:, i].min():.6f}, {samples[:, i].max():.6f}]",
                     f"{samples[:, i].max() - samples[:, i].min():.2e}"))
    return rows


def _chain_rhs(numeric, x):
    q, qd = list(x[:2]), list(x[2:])
    return qd + list(numeric.acceleration(q, qd))


def mass_matrix_solve():
    """Enclose qdd = M(q)^-1 b for q2 in a box, against sampled float solves."""
    from models import double_pendulum as dp

    q2 = Interval(-1.75, -1.70)
    x = [Interval(2.3), q2, Interval(0.0), Interval(0.0)]
    M = Interval(np.zeros((2, 2)))
    m = dp.mass_matrix(x)
    for i in range(2):
        for j in range(2):
            M[i, j] = m[i][j]
    b = Interval([1.0, -2.0])
    qdd = solve(M, b)
    samples = []
    for t in np.linspace(-1.75, -1.70, 201):
        mp = np.array([[float(v) for v in row] for row in dp.mass_matrix([2.3, t, 0.0, 0.0])])
        samples.append(np.linalg.solve(mp, [1.0, -2.0]))
    samples = np.array(samples)
    assert qdd.contains(samples).all(), "solve misses a sampled solution"
    return [(f"qdd{i + 1}", f"[{qdd.lo[i]:.6f}, {qdd.hi[i]:.6f}]",
             f"[{samples[:, i].min():.6f}, {samples[:, i].max():.6f}]") for i in range(2)]


def double_pendulum_solve(pieces=256, samples=401):
    """Rows of (state, verified width at T = 1, sampled width, ratio) and the run time."""
    from scipy.integrate import solve_ivp

    from models import double_pendulum as dp
    from verified.solver import solve

    lo, hi = dp.initial_box()
    t0 = time.perf_counter()
    sol = solve(trace(dp.rhs, 4), Interval(lo, hi), (0.0, 1.0), subdivision=[pieces, 1, 1, 1])
    wall = time.perf_counter() - t0
    if not sol.success:
        return [("breakdown", f"t = {sol.t_reached:.3f}", sol.reason, "")], wall
    x1 = np.linspace(lo[0], hi[0], samples)
    y0 = np.concatenate([x1] + [np.full(samples, lo[i]) for i in (1, 2, 3)])
    ref = solve_ivp(lambda t, y: np.concatenate(dp.rhs(y.reshape(4, samples))), (0.0, 1.0), y0,
                    method="DOP853", rtol=1e-12, atol=1e-12).y[:, -1].reshape(4, samples)
    final = sol.boxes[-1]
    inside = ((final.lo[:, None, :] - 1e-9 <= ref.T[None]) & (ref.T[None] <= final.hi[:, None, :] + 1e-9)).all(-1).any(0)
    assert inside.all(), "a sampled trajectory is outside the verified enclosure"
    w = sol.hull.width()[-1]
    true_w = ref.max(axis=1) - ref.min(axis=1)
    rows = [(f"x{i + 1}", f"{w[i]:.6f}", f"{true_w[i]:.6f}", f"{w[i] / true_w[i]:.4f}") for i in range(4)]
    return rows, wall


def run():
    t0 = time.perf_counter()
    print("1) Pendulum (paper 5.1): energy H over the initial box, by interval evaluation")
    print(_table(pendulum_energy(), ["pieces", "enclosure of H [J]", "width", "/ sampled", "ms"]))
    print("\n2) Double pendulum (paper eq. 22): accelerations over the initial box (25)")
    print(_table(double_pendulum_rhs(), ["model", "state", "enclosure", "width"]))
    print("\n3) Double pendulum mass matrix over q2 in [-1.75, -1.70]: verified solve of M qdd = b")
    print(_table(mass_matrix_solve(), ["", "verified enclosure", "sampled range"]))
    rows, wall = double_pendulum_solve()
    print(f"\n4) Double pendulum, verified solver to T = 1, initial box split into 256 pieces ({wall:.1f} s)")
    print(_table(rows, ["state", "verified width", "sampled width", "ratio"]))
    print(f"\nEvery enclosure above contains all sampled float values. ({time.perf_counter() - t0:.1f} s)")
    return 0
