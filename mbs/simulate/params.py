"""The uncertain parameters of a run: a chain's ``params`` checked for their form,
the parameter box :func:`verified.solver.solve` gets (by name or in order), that box cut
into pieces (``param_subdivision``), and the record a :class:`~mbs.simulate.Simulation`
keeps of them (``sol.params``)."""
from __future__ import annotations

import itertools

import numpy as np

from verified.arith.interval import Interval, _as_interval

from ..system import System
from ..uncertain import parse_value


def solver_params(run, params, param_subdivision):
    """``(initial box, parameter box or None)`` for ``solve`` of ``run``
    (:class:`mbs.simulate.model.Resolved`): a chain's parameters and a closed loop's are
    in its System (``params`` was turned into them), a bare System's come from
    ``params``; with ``param_subdivision`` one initial box per parameter piece."""
    system = run.system
    own = (run.masses is not None and system.params) or run.loop is not None
    ode = _system_params(system, None if own else params)
    box = run.box
    if param_subdivision:
        box, ode = _split_params(box, ode, system, param_subdivision, run.subdivision)
    return box, ode


def require_dict(params, name, chain=None, names=()):
    if not isinstance(params, dict):
        syms = list(names) or (sorted(str(x) for x in chain.free_symbols) if chain is not None else [])
        own = f", or the model's own parameters by name: {{{', '.join(repr(x) + ': [lo, hi]' for x in syms)}}}" \
            if syms else ""
        raise ValueError(f"params for the chain model {name!r} must be a dict such as "
                         "{'payload': {'link': ..., 'mass': [lo, hi]}, 'mass_scale': [lo, hi], "
                         f"'damping': {{joint: [lo, hi]}}}}{own} (see mbs.uncertain), got {type(params).__name__}")


def _system_params(system: System, params):
    """The ODE parameters for solve: ``params`` (a dict by name, or a sequence in the
    order of ``system.rhs.param_names``), default ``system.params``."""
    names = system.rhs.param_names
    if params is None:
        if not names:
            return None
        params = system.params
        if not params:
            raise ValueError(f"{system.name}: the ODE has parameters {', '.join(names)}: pass params")
    if isinstance(params, dict):
        unknown = [k for k in params if k not in names]
        if unknown:
            raise ValueError(f"params: unknown parameter(s) {', '.join(map(repr, unknown))} for {system.name!r}"
                             + (f"; its parameters: {', '.join(names)}" if names else "; it has no parameters"))
        missing = [k for k in names if k not in params]
        if missing:
            raise ValueError(f"params: missing value for {', '.join(map(repr, missing))} ({system.name!r} "
                             f"has parameters {', '.join(names)})")
        pairs = [parse_value(params[k], f"params {k}") for k in names]
        return Interval(np.array([a for a, _ in pairs]), np.array([b for _, b in pairs]))
    return params


def _split_params(box, ode_params, system, pieces: dict, subdivision):
    """(boxes (K, n), params (K, p)): the parameter box cut into a grid of ``pieces``."""
    names = list(system.rhs.param_names)
    if not isinstance(pieces, dict):
        raise ValueError(f"param_subdivision must be a dict {{parameter name: pieces}}, got {pieces!r}")
    if subdivision is not None:
        raise ValueError("param_subdivision cannot be combined with subdivision (one initial box per parameter piece)")
    if ode_params is None or ode_params.ndim != 1:
        raise ValueError("param_subdivision needs uncertain parameters (one parameter box)")
    if box.ndim != 1:
        raise ValueError("param_subdivision needs a single initial box")
    cuts = []
    for j, k in enumerate(names):
        m = pieces.get(k, 1)
        if isinstance(m, bool) or not isinstance(m, (int, np.integer)) or m < 1:
            raise ValueError(f"param_subdivision[{k!r}]: expected a positive integer, got {m!r}")
        lo, hi = float(ode_params.lo[j]), float(ode_params.hi[j])
        e = np.linspace(lo, hi, int(m) + 1)
        e[0], e[-1] = lo, hi
        cuts.append(list(zip(e[:-1], e[1:])))
    unknown = [k for k in pieces if k not in names]
    if unknown:
        raise ValueError(f"param_subdivision: unknown parameter(s) {', '.join(map(repr, unknown))}; "
                         f"parameters: {', '.join(names)}")
    rows = list(itertools.product(*cuts))
    plo = np.array([[a for a, _ in r] for r in rows])
    phi = np.array([[b for _, b in r] for r in rows])
    K = len(rows)
    X = Interval(np.tile(np.asarray(box.lo, float), (K, 1)), np.tile(np.asarray(box.hi, float), (K, 1)))
    return X, Interval(plo, phi)


def params_record(system: System, ode_params) -> dict:
    """{name: (lo, hi)} of the parameters a run used (their hull over the boxes)."""
    names = system.rhs.param_names
    if not names or ode_params is None:
        return {}
    try:
        p = _as_interval(ode_params)
    except (TypeError, ValueError):
        return {}
    lo = np.min(np.asarray(p.lo, float).reshape(-1, len(names)), axis=0)
    hi = np.max(np.asarray(p.hi, float).reshape(-1, len(names)), axis=0)
    return {k: (float(a), float(b)) for k, a, b in zip(names, lo, hi)}
