"""What :func:`mbs.simulate.simulate` makes of its settings before it runs: the
consistency-test defaults per mode, the output times, the initial box, the keywords it
passes on to :func:`verified.solver.solve` (an unknown one names ``simulate``) and the
defaults it fills in for a run that names its method by the old signature's settings."""
from __future__ import annotations

import difflib
import inspect

import numpy as np

import verified.solver
from verified.arith.interval import Interval, _as_interval
from verified.methods import METHOD_FIELDS

from ..modes import ALL_MODES

#: consistency-test settings per mode (the paper's: 0.1 s / 10 parts in mode (ii),
#: 0.01 s / 50 parts in mode (iii)); the fields of :mod:`mbs.modes`
TEST_DEFAULTS = {m.name: dict(test_interval=m.test_interval, test_splits=m.test_splits)
                 for m in ALL_MODES if m.energy_test}


def output_times(t0: float, t_end: float, output_dt: float | None) -> np.ndarray:
    """Output times ``t0 + k * output_dt`` (each computed directly, never accumulated),
    plus ``t_end`` when it is not a multiple."""
    if output_dt is None:
        return np.array([t_end])
    if not (np.isfinite(output_dt) and output_dt > 0):
        raise ValueError(f"output_dt must be a positive number of seconds, got {output_dt!r}")
    k = np.arange(1, int(np.floor((t_end - t0) / output_dt * (1 + 1e-12))) + 1)
    ts = t0 + k * output_dt
    ts = ts[ts <= t_end]
    if ts.size == 0 or ts[-1] < t_end * (1 - 1e-12):
        ts = np.append(ts, t_end)
    return ts


def initial_box(x0, n: int, name: str) -> Interval:
    if isinstance(x0, tuple) and len(x0) == 2 and not isinstance(x0[0], Interval):
        lo, hi = (np.asarray(v, dtype=float) for v in x0)
        x0 = Interval(lo, hi)
    try:
        box = _as_interval(x0)
    except Exception as e:
        raise ValueError(f"x0 must be an Interval or a (lo, hi) pair of arrays: {e}") from None
    if box.shape[-1] != n:
        raise ValueError(f"{name} has {n} states, but the initial box has shape {box.shape}")
    return box


def _legacy_method(method, solver_kwargs: dict) -> bool:
    """Whether the run names its method by the old signature's settings (``order``,
    ``set_order``, ...; no ``method``): then the defaults that method needs with a
    controller or parameters are filled in as before (the methods of
    :mod:`verified.methods` carry their own)."""
    return method is None and any(k in solver_kwargs for k in METHOD_FIELDS)


def method_defaults(method, solver_kwargs: dict, *, controlled: bool, with_params: bool) -> None:
    """Fill in, in ``solver_kwargs``, the settings the method named by the old
    signature's settings (:func:`_legacy_method`) needs, where the caller set none:
    ``arithmetic="affine"`` under control, ``error_basis="auto"`` with parameters (the
    methods of :mod:`verified.methods` carry their own)."""
    if not _legacy_method(method, solver_kwargs):
        return
    if controlled and "arithmetic" not in solver_kwargs:
        # a controller doubles the graph's depth; interval arithmetic breaks down early
        # where affine completes (docs/lab/code_notes.md)
        solver_kwargs["arithmetic"] = "affine"
    if with_params and "error_basis" not in solver_kwargs:
        # with parameters the "qr" error basis breaks down early, "auto" does not
        # (docs/lab/code_notes.md)
        solver_kwargs["error_basis"] = "auto"


def check_solver_kwargs(kwargs: dict, front):
    """Unknown keyword arguments name :func:`simulate` (not the solver it calls);
    ``front``: ``simulate`` itself, whose own keywords are offered as corrections too."""
    ours = set(inspect.signature(front).parameters) - {"solver_kwargs"}
    sig = inspect.signature(verified.solver.solve)  # (mbs.simulate.solve may be a test's wrapper)
    # (solve's **method_settings: the old signature's method settings, METHOD_FIELDS)
    theirs = {k for k, p in sig.parameters.items() if p.kind is not inspect.Parameter.VAR_KEYWORD}
    theirs = (theirs | set(METHOD_FIELDS)) - {"ode", "x0", "t_span", "t_eval", "params", "subdivision",
                                              "consistency", "progress", "method"}
    # names users bring from scipy's solve_ivp and what they are called here
    known = {"t_eval": "output_dt", "rtol": "tol", "atol": "tol", "t_span": "t_end"}
    for k in kwargs:
        if k not in theirs:
            close = [known[k]] if k in known else difflib.get_close_matches(k, sorted(ours | theirs), n=1)
            raise TypeError(f"simulate() got an unexpected keyword argument {k!r}"
                            + (f" (did you mean {close[0]!r}?)" if close else "")
                            + f"; solver settings it passes on: {', '.join(sorted(theirs))}")
