"""Command line::

    python -m mbs simulate SCENE --out DIR [--mode i|ii|iii] [--t-end T] [--output-dt DT]
                                 [--samples N] [--no-figures]
    python -m mbs demo           # the paper's double pendulum in modes i, ii, iii
    python -m mbs check MODEL    # our models against Pinocchio
    python -m mbs bench [--quick] [--out DIR]

``simulate`` writes DIR/result.json (see :mod:`mbs.results`) and the figures
(:mod:`mbs.figures`): enclosures.png (Fig. 5), and in modes ii/iii
reduction_area.png (Fig. 2) and consistency_plane.png (Fig. 3). SCENE is a TOML file
(:mod:`mbs.scene`) or the name of a shipped scene (``double_pendulum_paper``).
Exit codes: 0 done (also for a break-down, which is a result), 1 a sampled
trajectory escaped the enclosure (a bug: please report), 2 bad input.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # one line, exit 2 (argparse's default prints usage too)
        self.exit(2, f"{self.prog}: error: {message}\n")


def _fail(msg: str, code: int = 2) -> int:
    print(f"error: {msg}", file=sys.stderr)
    return code


def cmd_simulate(args) -> int:
    from .scene import SceneError, load_scene, MODES
    from . import runner

    try:
        scene = load_scene(args.scene)
        if args.mode is not None and args.mode not in MODES:
            raise SceneError(f"--mode {args.mode!r} is not one of {', '.join(MODES)}")
        for flag, v in (("--t-end", args.t_end), ("--output-dt", args.output_dt)):
            if v is not None and not (v > 0 and v < float("inf")):
                raise SceneError(f"{flag} must be a positive finite number, got {v}")
        if args.samples is not None and args.samples < 0:
            raise SceneError(f"--samples must be >= 0, got {args.samples}")
        report = runner.run_scene(scene, args.out, mode=args.mode, t_end=args.t_end,
                                  output_dt=args.output_dt, samples=args.samples,
                                  figures=not args.no_figures, log=print)
    except SceneError as e:
        return _fail(str(e))
    return 1 if report.get("escaped") else 0


def cmd_check(args) -> int:
    from . import ModelError
    from .check import compare_with_pinocchio, format_report, max_error
    from models.registry import get

    try:
        chain = get(args.model)
    except ModelError as e:
        return _fail(str(e))
    t0 = time.perf_counter()
    rep = compare_with_pinocchio(chain, symbolic=not args.numeric_only)
    print(format_report({args.model: rep}))
    err = max_error(rep)
    ok = err <= args.tol
    print(f"\nmax relative error {err:.2e} ({'ok' if ok else 'FAILS'} at tolerance {args.tol:g}; "
          f"{time.perf_counter() - t0:.1f} s)")
    return 0 if ok else 1


def main(argv=None):
    parser = _Parser(prog="python -m mbs", description="Guaranteed simulation of multibody systems.")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)
    p = sub.add_parser("simulate", help="run a scene file; write result.json and figures")
    p.add_argument("scene", help="TOML scene file (or the name of a shipped scene)")
    p.add_argument("--out", required=True, help="output directory")
    p.add_argument("--mode", help="i, ii or iii (overrides the scene)")
    p.add_argument("--t-end", type=float, help="horizon [s] (overrides the scene)")
    p.add_argument("--output-dt", type=float, help="output step [s] (overrides the scene)")
    p.add_argument("--samples", type=int, default=None,
                   help="check against N sampled true trajectories and overlay them on the figure "
                        "(default 64; 0: none)")
    p.add_argument("--no-figures", action="store_true", help="write result.json only")
    p = sub.add_parser("demo", help="the paper's double pendulum in modes i, ii, iii (about a minute)")
    p.add_argument("--out", default="out/demo", help="where the figures go (default out/demo)")
    p = sub.add_parser("check", help="compare a ready model with Pinocchio")
    p.add_argument("model", help="a name from models.registry.NAMES (e.g. ur5, puma560)")
    p.add_argument("--tol", type=float, default=1e-9)
    p.add_argument("--numeric-only", action="store_true", help="skip the symbolic model")
    p = sub.add_parser("bench", help="work-precision table and stress tests (docs/benchmarks.md)")
    p.add_argument("--quick", action="store_true", help="small fast version (used by the tests)")
    p.add_argument("--out", default=None, help="write the report and the plot here")
    args = parser.parse_args(argv)
    if args.command == "simulate":
        return cmd_simulate(args)
    if args.command == "check":
        return cmd_check(args)
    if args.command == "bench":
        from .bench import run as bench_run
        return bench_run(quick=args.quick, out=args.out)
    if args.command == "demo":
        from .demo import run
        return run(out=args.out)
    return 2


if __name__ == "__main__":
    sys.exit(main())
