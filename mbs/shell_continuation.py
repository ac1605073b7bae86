"""A passive chain's run carried on past a break-down by the energy shell (issue 43, item 3).

With ``simulate(..., energy_shell=True)`` on a chain without controller or uncertain
parameters, a run whose Taylor sets break down (a chaotic free fall) does not end
there: :func:`carry_on` continues it to ``t_end`` with the crude but sound boxes of
:func:`verified.consistency.shell_boxes.continue_in_shell` -- every joint rate bounded by the
energy (``|qd_i| <= sqrt(2 (hmax - min V) c_i)`` with the chain's proven
``c_i >= (M(q)^-1)_ii`` for every ``q``, :func:`mbs.shell_bounds.inverse_mass_bounds`),
the positions grown by that rate. The result says so: ``status="completed"``, its
``reason`` names the time where the sets gave up and the shell took over,
``stats["shell_from"]`` is that time and ``stats["shell_speed"]`` the rate bounds.

Where that cannot be done the run is returned as it was (a break-down), with the
reason saying why the shell did not carry it on (uncertain parameters, a prismatic
joint, states besides ``(q, qd)``).
"""
from __future__ import annotations

import numpy as np

from verified.consistency.energy_shell import EnergyShellHook
from verified.consistency.shell_boxes import continue_in_shell

from .shell_bounds import inverse_mass_bounds

__all__ = ["carry_on"]

_BOUNDS: dict = {}  # chain fingerprint -> inverse_mass_bounds (a few seconds on a 7-dof arm)


def _bounds(chain):
    key = chain.fingerprint()
    if key not in _BOUNDS:
        _BOUNDS[key] = inverse_mass_bounds(chain)
    return _BOUNDS[key]


def carry_on(sol, masses, hooks, box, t_eval, t_end: float, *, quiet: bool = False):
    """``sol`` carried on to ``t_end`` with the energy shell's boxes when it broke down
    (module docstring); ``masses``: the run's chain record (``.chain``, ``.cparams``),
    ``hooks``: the run's hooks (with ``simulate(energy_shell=True)`` one
    :class:`~verified.consistency.energy_shell.EnergyShellHook`; without one the shell is
    the chain's numeric model's, over ``box``), ``box``: the initial box. Anything else
    (completed, stopped, no chain) is returned unchanged. ``quiet`` (the default
    ``energy_shell=None``, which nobody asked for): only a run whose every piece broke
    down is carried on, and where the shell cannot carry it on, its reason is not
    appended to ``sol.reason``."""
    if sol.status != "breakdown" or masses is None:
        return sol
    hook = next((h for h in hooks if isinstance(h, EnergyShellHook)), None)
    chain = masses.chain
    why = None
    if quiet and sol.surviving is not None:
        # (some pieces went on: their enclosures and the per-piece record are worth more
        # than the shell's boxes over the hull of them all)
        why = "pieces survived"
    elif getattr(masses, "cparams", None) is not None and masses.cparams.n:
        why = "uncertain parameters (no bound of M(q)^-1 over the parameter box)"
    elif any(b.joint.kind != "revolute" for b in chain.bodies):
        why = "a prismatic joint (its position has no period)"
    elif sol.hull.shape[-1] != 2 * chain.n:
        why = f"states besides (q, qd) ({sol.hull.shape[-1]} states)"
    if why is None:
        c = _bounds(chain)
        if not np.all(np.isfinite(c)):
            why = "no proven bound of (M(q)^-1)_ii for q" + ", q".join(str(i + 1) for i in np.flatnonzero(~np.isfinite(c)))
    if why is not None:
        if not quiet:
            sol.reason += f"; the energy shell cannot carry the run on: {why}"
        return sol
    try:
        if hook is None:
            from .simulate.hooks import energy_shell_of
            hook = EnergyShellHook(*energy_shell_of(masses.num, box))
        return continue_in_shell(sol, hook.shell, hook.hmax, c, t_eval, t_end, start=box,
                                 periods=np.full(chain.n, 2.0 * np.pi))
    except ValueError as e:
        if not quiet:
            raise
        # (no finite speed bound: the break-down stands, as without the shell)
        sol.stats["shell_refused"] = str(e)
        return sol
