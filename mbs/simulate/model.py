"""From a model and a mode to what :func:`mbs.simulate.simulate` integrates: the
:class:`~mbs.system.System` (the modes and the models accepted: :mod:`mbs.simulate`),
the chain behind it for the M(q) > 0 checks (:mod:`.mass_matrix`) and, under control,
the closed loop. This module names no model: it asks :func:`mbs.robots.system_entry`
and :func:`mbs.robots.load_model`."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from verified.consistency.energy_rate import MODEL_RATES, check_energy_rate
from verified.arith.interval import Interval

from ..chain import Chain
from ..control import closed_loop
from ..errors import ModelError
from ..modes import Mode, get_mode
from ..robots import load_model, system_entry
from ..system import System
from ..uncertain import ChainParameters
from .mass_matrix import MassMatrix
from .options import initial_box
from .params import require_dict


@dataclass
class Resolved:
    """A model resolved for one run: the ``system`` to integrate, ``masses`` (the chain
    behind it for the M(q) > 0 checks; None for a bare System), ``loop`` (the closed loop
    under control, else None), the initial ``box`` (with the time state of a timed
    reference appended) and ``subdivision`` (extended over that state)."""

    system: System
    masses: MassMatrix | None
    loop: object
    box: Interval
    subdivision: object


def resolve(model, x0, mode, *, params, control, energy_rate: str, t0: float, t_end: float,
            subdivision) -> Resolved:
    """``model`` in ``mode`` from the initial box ``x0`` (the arguments of
    :func:`mbs.simulate.simulate`; under ``control`` a PD controller without ``q_ref``
    holds the centre of the initial q box)."""
    if control is None:
        system, masses = _system_and_chain(model, mode, energy_rate, params)
        return Resolved(system, masses, None, initial_box(x0, system.n, system.name), subdivision)
    n2 = _model_chain(model, params)[0].n * 2 if not isinstance(model, System) else model.n
    box = initial_box(x0, n2, str(model))
    q_init = np.asarray(box.hull(axis=0).mid() if box.ndim > 1 else box.mid(), float)[:n2 // 2]
    system, masses, loop = _controlled_system(model, mode, params, control, q_init)
    if loop.t_end_max is not None and t_end > loop.t_end_max * (1 + 1e-12):
        raise ValueError(f"t_end = {t_end:g} s is past the end of the reference trajectory "
                         f"({loop.t_end_max:g} s); the quintic is not continued past it")
    if loop.timed:  # the time as the last state, a point: t' = 1
        lo, hi = np.asarray(box.lo, float), np.asarray(box.hi, float)
        tcol = np.full(lo.shape[:-1] + (1,), t0)
        box = Interval(np.concatenate([lo, tcol], axis=-1), np.concatenate([hi, tcol], axis=-1))
        if subdivision is not None and not isinstance(subdivision, (int, np.integer)):
            subdivision = list(subdivision) + [1] * (system.n - len(list(subdivision)))
    return Resolved(system, masses, loop, box, subdivision)


def system_for(model, mode: str | Mode = "ii", *, energy_rate: str = "unsimplified", params=None, control=None,
               q_init=None) -> System:
    """The :class:`System` that ``mode`` integrates for ``model`` (see module docstring);
    ``params`` and ``control`` as for :func:`simulate` (``q_init``: the pose a PD
    controller without ``q_ref`` holds)."""
    if control is not None:
        return _controlled_system(model, mode, params, control, q_init)[0]
    return _system_and_chain(model, mode, energy_rate, params)[0]


def chain_state_names(model, params=None) -> tuple[str, ...]:
    """The states ``q1..qn, qd1..qdn`` of a chain model (a model name, a URDF or DH
    :class:`mbs.Chain`) without building its System, ``params`` checked against the chain
    (:class:`mbs.uncertain.ParameterError`): the states :func:`system_for` integrates for
    it, and under ``control`` those before the time state ``"t"``. A bare System raises
    ModelError, as under control."""
    n = _model_chain(model, params)[0].n
    return tuple(f"q{i + 1}" for i in range(n)) + tuple(f"qd{i + 1}" for i in range(n))


def _chain_system(chain, mode: Mode, energy_rate: str, name: str | None = None, cparams=None) -> System:
    name = name or getattr(chain, "name", "chain")
    if cparams is not None:
        if mode.symbolic:
            raise ValueError(f"{name}: uncertain parameters of a chain ({', '.join(cparams.names)}) are "
                             "supported in modes i and ii (the symbolic model of mode iii takes none)")
        rhs = cparams.rhs_graph()
        if not mode.energy_test:
            return System(name=name, rhs=rhs, params=cparams.as_dict(),
                          description="numeric model (crba/rnea) with parameters, no test")
        return System(name=name, rhs=rhs, energy=cparams.energy_graph(), energy_rate="derive", params=cparams.as_dict(),
                      description="numeric model with parameters; dH/dt by forward-mode AD of H along the ODE")
    if not mode.symbolic:
        num = chain.numeric()
        rhs = num.rhs_graph()
        if not mode.energy_test:
            return System(name=name, rhs=rhs, description="numeric model (crba/rnea), no test")
        return System(name=name, rhs=rhs, energy=num.energy_graph(), energy_rate="derive",
                      description="numeric model; dH/dt by forward-mode AD of H along the ODE")
    sym = chain.symbolic()
    rhs = sym.rhs_graph()
    energy = sym.energy_graph()
    rate = sym.energy_rate_graph(simplified=(energy_rate == "simplified"))
    return System(name=name, rhs=rhs, energy=energy, energy_rate=rate,
                  description=f"symbolic model (sympy); dH/dt {energy_rate}")


def _model_chain(model, params):
    """(chain, ChainParameters or None, name) of a chain model (for controllers)."""
    if isinstance(model, System):
        raise ModelError(f"{model.name}: controllers need a chain model (a model name, URDF or mbs.Chain), "
                         "not a bare System; write the torque into the System's rhs instead")
    if isinstance(model, str):
        name = model
        entry = system_entry(model)
        chain = entry.chain(params) if entry is not None else load_model(model)
    elif isinstance(model, Chain):
        chain, name = model, None
    else:
        raise TypeError(f"model must be a model name, an mbs.Chain or an mbs.system.System, "
                        f"got {type(model).__name__}")
    cp = None
    if params is not None or chain.free_symbols:
        require_dict(params if params is not None else {}, name or chain.name, chain)
        cp = ChainParameters(chain, params or {}, model_name=name)
    return chain, cp, name or chain.name


def _controlled_system(model, mode, params, control, q_init):
    """(System, MassMatrix, ClosedLoop) of ``model`` under ``control`` (modes i, ii)."""
    mode = get_mode(mode)
    if mode.symbolic:
        raise ValueError("controllers are supported in modes i and ii (the numeric model); "
                         "mode iii's symbolic models take no torque inputs")
    chain, cp, name = _model_chain(model, params)
    loop = closed_loop(chain, control, cp, q_init=q_init, model_name=name)
    rhs = loop.rhs_graph()
    pdict = {k: (float(a), float(b)) for k, a, b in zip(loop.param_names, loop.lo, loop.hi)}
    what = ", ".join(c.name for c in loop.controllers)
    if not mode.energy_test:
        system = System(name=name, rhs=rhs, params=pdict, description=f"numeric model under control ({what}), no test")
    else:
        system = System(name=name, rhs=rhs, energy=loop.energy_graph(), energy_rate=loop.energy_rate_graph(),
                        params=pdict, description=f"numeric model under control ({what}); "
                                                  "dH/dt = qd^T tau - qd^T D qd (eq. 7)")
    return system, MassMatrix(chain, cp), loop


def _system_and_chain(model, mode: str | Mode, energy_rate: str, params=None):
    """(System, MassMatrix of the chain behind it or None) -- the chain for the
    mass-matrix checks."""
    mode = get_mode(mode)
    check_energy_rate(energy_rate, MODEL_RATES, "simulate")
    if isinstance(model, System):
        if not mode.energy_test:
            model = System(name=model.name, rhs=model.rhs, params=model.params, description=model.description)
        elif not model.has_energy:
            raise ModelError(f"{model.name}: mode {mode} needs an energy graph (System.energy)")
        return model, None
    if isinstance(model, str):
        entry = system_entry(model)
        if entry is not None:
            # a registry System factory (the paper's models): its chain in modes i and
            # ii, its own System (hand-written, the same M) where it has one
            cp = None
            if params is not None:
                require_dict(params, model, names=getattr(entry, "param_names", ()))
            if params:
                chain = entry.chain(params)
                cp = ChainParameters(chain, params, model_name=model)
            else:
                chain = entry.chain()
            system = entry.system(mode, energy_rate, cp)
            if system is None:
                system = _chain_system(chain, mode, energy_rate, name=model, cparams=cp)
            return system, MassMatrix(chain, cp)
        chain = load_model(model)  # registry names, aliases (panda), example-robot-data:NAME, URDF paths
        name = model
    elif isinstance(model, Chain):
        chain = model
        name = None
    else:
        raise TypeError(f"model must be a model name, an mbs.Chain or an mbs.system.System, "
                        f"got {type(model).__name__}")
    if params is not None or chain.free_symbols:
        require_dict(params if params is not None else {}, name or chain.name, chain)
        cp = ChainParameters(chain, params or {}, model_name=name)
        return _chain_system(chain, mode, energy_rate, name=name, cparams=cp), MassMatrix(chain, cp)
    return _chain_system(chain, mode, energy_rate, name=name), MassMatrix(chain)
