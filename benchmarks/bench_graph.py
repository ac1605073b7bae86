"""Benchmark of expression-graph evaluation over batches of boxes.

Run:  python benchmarks/bench_graph.py [--batch 1000] [--repeats 5]

Graphs: the traced double-pendulum right-hand side of the paper's eq. (22) together
with its energy, eq. (24) (about 100 operations), and a random expression of 100
operations. For each: float evaluation, interval evaluation, float Jacobian and
interval Jacobian on a batch of boxes; wall time per call, per operation per call
(microseconds), the interval/float ratio, and the batch-1000 / batch-10 time ratio
(far below 100 when there is no Python loop over boxes).
"""
from __future__ import annotations

import argparse
import time

import numpy as np


from verified.graph import Graph, GraphBuilder, trace
from verified.arith.interval import Interval

M1 = M2 = L1 = L2 = 1.0
G = 9.81


def double_pendulum_rhs_and_energy(x, p):
    """[x_dot (eq. 22, A^-1 b written out with the factored determinant), H (eq. 24)]."""
    return double_pendulum_rhs_and_energy_params(x, [M1, M2, L1, L2, G])


def double_pendulum_rhs_and_energy_params(x, p):
    """Same with the parameters p = (m1, m2, l1, l2, g) as graph parameters (no folding)."""
    x1, x2, x3, x4 = x
    M1, M2, L1, L2, G = p
    c2, s2 = np.cos(x2), np.sin(x2)
    a11, a12 = M1 * L1 + M2 * (L1 + L2 * c2), M2 * L2 * c2
    a21, a22 = M2 * (L1 * c2 + L2), M2 * L2
    b1 = -G * (M1 + M2) * np.sin(x1) + M2 * L2 * s2 * (x3 + x4) ** 2
    b2 = -G * M2 * np.sin(x1 + x2) - M2 * L1 * s2 * x3**2
    det = M2 * L1 * L2 * (M1 + M2 * s2**2)
    # energy in absolute angles phi1 = x1, phi2 = x1 + x2
    phi2, w1, w2 = x1 + x2, x3, x3 + x4
    py1 = -L1 * np.cos(x1)
    py2 = py1 - L2 * np.cos(phi2)
    vx1, vy1 = L1 * np.cos(x1) * w1, L1 * np.sin(x1) * w1
    vx2, vy2 = vx1 + L2 * np.cos(phi2) * w2, vy1 + L2 * np.sin(phi2) * w2
    H = M1 * G * py1 + M2 * G * py2 + 0.5 * M1 * (vx1**2 + vy1**2) + 0.5 * M2 * (vx2**2 + vy2**2)
    return [x3, x4, (a22 * b1 - a12 * b2) / det, (a11 * b2 - a21 * b1) / det, H]


def random_graph(n_ops: int = 100, n_inputs: int = 4, n_outputs: int = 4, seed: int = 0) -> Graph:
    """A random expression DAG of ``n_ops`` operations, defined on all of R^n (log and
    sqrt get ``1 + sqr(.)`` arguments, tan a ``0.5*sin(.)`` one, divisions ``2 + cos(.)``)."""
    rng = np.random.default_rng(seed)
    b = GraphBuilder(n_inputs)
    pool = [b.input(i) for i in range(n_inputs)]
    one, half, two = b.const(1.0), b.const(0.5), b.const(2.0)

    def pick():
        # mostly recent nodes, so that almost everything is reachable from the outputs
        if rng.uniform() < 0.8:
            return pool[int(rng.integers(max(0, len(pool) - 6), len(pool)))]
        return pool[int(rng.integers(0, len(pool)))]

    graph = b.build(pool[-n_outputs:])
    while graph.n_ops < n_ops:
        a, c = pick(), pick()
        kind = rng.integers(0, 9)
        if kind == 0:
            v = b.add(a, c)
        elif kind == 1:
            v = b.sub(a, c)
        elif kind == 2:
            v = b.mul(a, b.sin(c))
        elif kind == 3:
            v = b.div(a, b.add(two, b.cos(c)))
        elif kind == 4:
            v = b.sqrt(b.add(one, b.sqr(a)))
        elif kind == 5:
            v = b.log(b.add(one, b.sqr(a)))
        elif kind == 6:
            v = b.atan(b.mul(a, c))
        elif kind == 7:
            v = b.tan(b.mul(half, b.sin(a)))
        else:
            v = b.mul(half, b.exp(b.sin(a)))
        pool.append(v)
        graph = b.build(pool[-n_outputs:])
    return graph


def make_graphs() -> dict[str, Graph]:
    names = ["x1", "x2", "x3", "x4"]
    return {
        "double_pendulum_rhs+H": trace(double_pendulum_rhs_and_energy, 4, input_names=names),
        "double_pendulum_rhs+H_params": trace(
            double_pendulum_rhs_and_energy_params, 4, 5, input_names=names, param_names=["m1", "m2", "l1", "l2", "g"]
        ),
        "random_100": random_graph(100),
    }


def _best_time(fn, repeats: int) -> float:
    fn()  # warm-up (numba compilation, caches)
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def _boxes(n: int, batch: int, seed: int = 1):
    rng = np.random.default_rng(seed)
    c = rng.uniform(-2, 2, size=(batch, n))
    r = rng.uniform(0, 0.05, size=(batch, n))
    return c, Interval(c - r, c + r)


def bench_graph(graph: Graph, batch: int = 1000, repeats: int = 5) -> dict:
    """Times (seconds per call) of the four evaluators on ``batch`` boxes, plus derived numbers."""
    X, box = _boxes(graph.n_inputs, batch)
    P = np.array([M1, M2, L1, L2, G])[: graph.n_params]
    Pbox = Interval(P)
    times = {
        "float": _best_time(lambda: graph.eval_float(X, P), repeats),
        "interval": _best_time(lambda: graph.eval_interval(box, Pbox), repeats),
        "jac_float": _best_time(lambda: graph.jacobian_float(X, P), repeats),
        "jac_interval": _best_time(lambda: graph.jacobian_interval(box, Pbox), repeats),
    }
    return {
        "n_ops": graph.n_ops,
        "batch": batch,
        "times": times,
        "us_per_op": {k: 1e6 * t / graph.n_ops for k, t in times.items()},
        "interval_over_float": times["interval"] / times["float"],
        "jac_interval_over_jac_float": times["jac_interval"] / times["jac_float"],
    }


def batch_scaling(graph: Graph, small: int = 10, large: int = 1000, repeats: int = 5) -> dict:
    """Time ratio large/small batch per evaluator (a per-box Python loop would give ~large/small)."""
    t_small = bench_graph(graph, small, repeats)["times"]
    t_large = bench_graph(graph, large, repeats)["times"]
    return {k: t_large[k] / t_small[k] for k in t_small}


def run(batch: int = 1000, repeats: int = 5, small: int = 10) -> list[dict]:
    """Benchmark rows, one per graph (used by ``main`` and by the tests with small sizes)."""
    rows = []
    for name, graph in make_graphs().items():
        row = bench_graph(graph, batch, repeats)
        row["name"] = name
        row["scaling"] = batch_scaling(graph, small, batch, repeats)
        rows.append(row)
    return rows


def format_table(rows: list[dict]) -> str:
    kinds = ["float", "interval", "jac_float", "jac_interval"]
    lines = []
    for row in rows:
        lines.append(f"{row['name']}: {row['n_ops']} ops, batch {row['batch']} boxes")
        lines.append(f"  {'evaluator':<14}{'ms/call':>10}{'us/op/call':>12}{'batch ' + str(row['batch']) + '/' + 'small':>18}")
        for k in kinds:
            lines.append(
                f"  {k:<14}{1e3 * row['times'][k]:>10.3f}{row['us_per_op'][k]:>12.2f}{row['scaling'][k]:>18.1f}"
            )
        lines.append(
            f"  interval/float = {row['interval_over_float']:.1f}x, "
            f"jac_interval/jac_float = {row['jac_interval_over_jac_float']:.1f}x"
        )
    return "\n".join(lines)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--batch", type=int, default=1000)
    ap.add_argument("--small", type=int, default=10, help="small batch for the scaling check")
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args(argv)
    print(format_table(run(args.batch, args.repeats, args.small)))


if __name__ == "__main__":
    main()
