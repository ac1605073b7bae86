"""Command line::

    python -m mbs simulate SCENE --out DIR [--mode i|ii|iii] [--t-end T] [--output-dt DT]
                                 [--samples N] [--no-figures] [--max-wall SECONDS]
                                 [--workers N|auto] [--scheduler tcp://host:port]
    python -m mbs demo           # the paper's double pendulum in modes i, ii, iii
    python -m mbs check MODEL    # our models against Pinocchio (ur5, panda, example-robot-data:NAME,
                                 # a URDF path)
    python -m mbs bench [--quick] [--out DIR]

``simulate`` writes DIR/result.json (see :mod:`mbs.app.results`) and the figures
(:mod:`mbs.app.figures`): enclosures.png (Fig. 5), and in modes ii/iii
reduction_area.png (Fig. 2) and, when an energy test pruned a sub-box,
consistency_plane.png (Fig. 3). It ends with a table: per state at the last output
time the enclosure's width, the spread of the sampled trajectories and their ratio,
the worst ratio and the method that ran (also in result.json, "tightness"). On a
terminal a progress bar names the phase (model, compiling, solving, sampling, frame
enclosures, figures) with its clock from the command's start, and a first run says
when the numba kernels compile (first run only). SCENE is a TOML file
(:mod:`mbs.app.scene`) or the name of a shipped scene (``double_pendulum_paper``).
The console script ``mbs`` is the same command (``mbs simulate SCENE --out DIR``).

Exit codes of ``simulate``: 0 completed (every enclosure verified up to t_end, every
sampled trajectory inside), 1 a sampled trajectory escaped the enclosure (a bug:
please report), 2 bad input (scene, options, model), 3 the integration broke down
before t_end (result.json holds everything verified up to the break-down; the
printed widths are those at the break-down, not at t = 0), 4 stopped by
``--max-wall SECONDS``, 130 interrupted by Ctrl-C. In the last two cases too,
result.json holds everything verified so far (status "stopped" / "interrupted").
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from .. import ModelError
from ..check import compare_with_pinocchio, format_report, max_error
from ..robots import load_model


#: exit codes of ``simulate`` (see the module docstring)
EXIT_ESCAPED, EXIT_BAD_INPUT, EXIT_BREAKDOWN, EXIT_STOPPED, EXIT_INTERRUPTED = 1, 2, 3, 4, 130


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # one line, exit 2 (argparse's default prints usage too)
        self.exit(2, f"{self.prog}: error: {message}\n")


def _fail(msg: str, code: int = 2) -> int:
    print(f"error: {msg}", file=sys.stderr)
    return code


def cmd_simulate(args) -> int:
    # (import here: scene and runner load verified and numba, ~0.4 s that --help does not need)
    from .scene import SceneError, load_scene, MODES
    from . import runner

    try:
        batch = runner.scenario_batch(args.scene)
        scene = load_scene(args.scene) if batch is None else batch[0][1]
        if args.mode is not None and args.mode not in MODES:
            raise SceneError(f"--mode {args.mode!r} is not one of {', '.join(MODES)}")
        for flag, v in (("--t-end", args.t_end), ("--output-dt", args.output_dt)):
            if v is not None and not (v > 0 and v < float("inf")):
                raise SceneError(f"{flag} must be a positive finite number, got {v}")
        if args.samples is not None and args.samples < 0:
            raise SceneError(f"--samples must be >= 0, got {args.samples}")
        if args.max_wall is not None and not (args.max_wall > 0 and args.max_wall < float("inf")):
            raise SceneError(f"--max-wall must be a positive number of seconds, got {args.max_wall}")
        workers, client = _parallel_flags(args, runner)
        if batch is not None:  # [[scenarios]]: one job, scenarios.json
            report = runner.run_scenarios(batch, args.out, mode=args.mode, t_end=args.t_end,
                                          output_dt=args.output_dt, samples=args.samples, log=print,
                                          max_wall=args.max_wall, workers=workers, client=client)
        else:
            report = runner.run_scene(scene, args.out, mode=args.mode, t_end=args.t_end,
                                      output_dt=args.output_dt, samples=args.samples,
                                      figures=not args.no_figures, log=print, max_wall=args.max_wall,
                                      workers=workers, client=client, started=args.started)
    except SceneError as e:
        return _fail(str(e))
    except KeyboardInterrupt:  # before the integration started: nothing verified yet
        print("interrupted before the integration started; nothing written", file=sys.stderr)
        return EXIT_INTERRUPTED
    status = report["status"] if report.get("solution") is None else report["solution"].status
    if report.get("escaped"):
        return EXIT_ESCAPED
    if status == "interrupted" or report.get("interrupted"):
        return EXIT_INTERRUPTED
    if status == "stopped":
        return EXIT_STOPPED
    if status != "completed":
        return EXIT_BREAKDOWN
    return 0


def _parallel_flags(args, runner):
    """(workers, client) from --workers / --scheduler (issue 16, verified/execution/)."""
    from .scene import SceneError  # (import here: see cmd_simulate)
    workers = args.workers
    if workers != "auto":
        try:
            workers = int(workers)
        except ValueError:
            workers = 0
        if workers < 1:
            raise SceneError(f"--workers must be 'auto' or an integer >= 1, got {args.workers!r}")
    client = runner.scheduler_client(args.scheduler) if args.scheduler else None
    return workers, client


def cmd_check(args) -> int:
    try:
        chain = load_model(args.model)
    except ModelError as e:
        return _fail(str(e))
    except Exception as e:  # noqa: BLE001 - unreadable URDF and the like: bad input
        return _fail(f"cannot load {args.model!r}: {type(e).__name__}: {e}")
    t0 = time.perf_counter()
    try:
        rep = compare_with_pinocchio(chain, symbolic=not args.numeric_only)
    except ModelError as e:  # e.g. Pinocchio's stricter URDF parser refuses the file
        return _fail(str(e))
    print(format_report({args.model: rep}))
    err = max_error(rep)
    ok = err <= args.tol
    print(f"\nmax relative error {err:.2e} ({'ok' if ok else 'FAILS'} at tolerance {args.tol:g}; "
          f"{time.perf_counter() - t0:.1f} s)")
    return 0 if ok else 1


def main(argv=None):
    started = time.time()  # the progress bar's clock counts from here (mbs.progress)
    prog = "mbs" if Path(sys.argv[0]).name == "mbs" else "python -m mbs"
    parser = _Parser(prog=prog, description="Guaranteed simulation of multibody systems.",
                     epilog="simulate exits with 0 (completed), 1 (a sampled trajectory escaped: a bug), "
                            "2 (bad input), 3 (break-down before t_end), 4 (stopped by --max-wall) or "
                            "130 (interrupted by Ctrl-C); in the last two, result.json holds what is verified")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)
    p = sub.add_parser("simulate", help="run a scene file; write result.json and figures")
    p.add_argument("scene", help="TOML scene file (or the name of a shipped scene)")
    p.add_argument("--out", required=True, help="output directory")
    p.add_argument("--mode", help="i, ii or iii (overrides the scene)")
    p.add_argument("--t-end", type=float, help="horizon [s] (overrides the scene)")
    p.add_argument("--output-dt", type=float, help="output step [s] (overrides the scene)")
    p.add_argument("--samples", type=int, default=None,
                   help="check against exactly N sampled true trajectories (initial states and "
                        "uncertain parameters) and overlay them on the figure (default 64; 0: none)")
    p.add_argument("--no-figures", action="store_true", help="write result.json only")
    p.add_argument("--max-wall", type=float, default=None, metavar="SECONDS",
                   help="stop the integration after SECONDS of wall-clock time and write what is verified "
                        "(exit 4; Ctrl-C does the same with exit 130). Checked between steps: the step "
                        "under way when the time is up still finishes")
    p.add_argument("--workers", default="auto", metavar="N",
                   help="run the initial boxes in chunks on N local worker processes (Dask; default 'auto': "
                        "every core when there are >= 128 pieces and dask is installed; 1: one batch in-process)")
    p.add_argument("--scheduler", default=None, metavar="ADDR",
                   help="run the chunks on an existing Dask cluster, e.g. tcp://host:8786 (a one-line error "
                        "after 10 s when it cannot be reached)")
    p = sub.add_parser("demo", help="the paper's double pendulum in modes i, ii, iii (about a minute)")
    p.add_argument("--out", default="out/demo", help="where the figures go (default out/demo)")
    p = sub.add_parser("check", help="compare a ready model with Pinocchio")
    p.add_argument("model", help="a model name (ur5, panda, puma560, ...), example-robot-data:NAME "
                                 "or a URDF file path (what a scene's [model] accepts)")
    p.add_argument("--tol", type=float, default=1e-9)
    p.add_argument("--numeric-only", action="store_true", help="skip the symbolic model")
    p = sub.add_parser("bench", help="work-precision table and stress tests (benchmarks.md in --out)")
    p.add_argument("--quick", action="store_true", help="small fast version (used by the tests)")
    p.add_argument("--out", default=None, help="write benchmarks.md and bench_work_precision.png here "
                                               "(default out/bench; --quick: a temporary directory; a "
                                               "checkout's docs/benchmarks.md: --out docs)")
    args = parser.parse_args(argv)
    args.started = started
    if args.command == "simulate":
        return cmd_simulate(args)
    if args.command == "check":
        return cmd_check(args)
    if args.command == "bench":
        from .bench import run as bench_run  # (import here: see cmd_simulate)
        return bench_run(quick=args.quick, out=args.out)
    if args.command == "demo":
        from .demo import run  # (import here: see cmd_simulate)
        return run(out=args.out, started=started)
    return 2


if __name__ == "__main__":
    sys.exit(main())
