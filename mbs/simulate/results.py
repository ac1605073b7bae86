"""What :func:`mbs.simulate.simulate` returns and how runs are compared: the
:class:`Simulation` (the solver's Solution as ``solve`` made it, plus what only the
modeling side knows) and the width deviations between two runs."""
from __future__ import annotations

from dataclasses import dataclass, field, fields

import numpy as np

from verified.solver import Solution

from ..frames import attach_frames


@dataclass(repr=False)
class Simulation(Solution):
    """What :func:`simulate` returns: the solver's :class:`verified.solver.Solution`
    (every field and property of it) plus what only the modeling side knows.

    Attributes (beyond ``Solution``'s)
    ----------------------------------
    mode : str
        The simulation mode, "i", "ii" or "iii" (paper sec. 5.2; :mod:`mbs.modes`).
    params : dict
        The uncertain physical parameters the run covered, ``{name: (lo, hi)}``.
    control : object or None
        The closed loop (:mod:`mbs.control`) when a controller drove the joints.
    frame : mbs.frames.Frames or None
        Enclosures of the chain's frames over the run (``sol.frame("tool0")``), for runs
        of a chain (:func:`mbs.frames.attach_frames`); None for a bare System.
    """

    mode: str = ""
    params: dict = field(default_factory=dict)
    control: object = None
    frame: object = None

    @classmethod
    def of(cls, sol: Solution, **extra) -> "Simulation":
        """``sol``'s fields (shared, not copied) with ``extra`` set."""
        return cls(**{f.name: getattr(sol, f.name) for f in fields(Solution)}, **extra)


def as_simulation(sol: Solution, mode: str, run, record: dict) -> Simulation:
    """``sol`` as a :class:`Simulation` of ``run`` (a :class:`mbs.simulate.model.Resolved`)
    in ``mode`` with the parameters ``record``: its state names, its ``surviving`` part
    likewise, and for a chain the enclosures of its frames."""
    loop, system, masses = run.loop, run.system, run.masses
    sol = Simulation.of(sol, mode=mode, params=record, control=loop)
    sol.state_names = system.state_names
    if sol.surviving is not None:  # (the pieces that went on after others broke down; no frames)
        sol.surviving = Simulation.of(sol.surviving, mode=mode, params=record, control=loop)
        sol.surviving.state_names = system.state_names
    if masses is not None:
        attach_frames(sol, masses.chain, loop.cparams if loop is not None else getattr(masses, "cparams", None))
    return sol


class WidthDeviations(np.ndarray):
    """Largest ``|diam a(t) - diam b(t)|`` per state (an ndarray (n,)) that also says
    where it was taken: ``times`` (the output times compared, every one both solutions
    reached), ``argmax_t`` (n,) (the output time of each maximum), ``only_one`` (output
    times only one solution reached: the other broke down or stopped earlier)."""

    times: np.ndarray
    argmax_t: np.ndarray
    only_one: np.ndarray
    state_names: tuple

    def __array_finalize__(self, obj):
        for k in ("times", "argmax_t", "only_one"):
            setattr(self, k, getattr(obj, k, np.zeros(0)))
        self.state_names = getattr(obj, "state_names", ())

    def describe(self) -> str:
        """One line: the deviations, where they occur and what was compared."""
        names = self.state_names or tuple(f"x{i + 1}" for i in range(self.size))
        parts = ", ".join(f"{n} {float(v):.4g} (t = {float(t):g})"
                          for n, v, t in zip(names, np.asarray(self), self.argmax_t))
        ts = self.times
        head = (f"largest width differences over {ts.size} output times t = {ts[0]:g} .. {ts[-1]:g}: "
                if ts.size else "no common output times: ")
        tail = ""
        if self.only_one.size:
            tail = (f"; {self.only_one.size} later output time(s) up to t = {self.only_one[-1]:g} reached by one "
                    "solution only (not compared)")
        return head + parts + tail


def width_deviations(a: Solution, b: Solution) -> WidthDeviations:
    """Largest ``|diam a(t) - diam b(t)|`` per state over every output time both
    solutions reach (the paper's comparison of modes (ii) and (iii): 0.0018, 0.0072,
    0.0066, 0.0444). Returns a :class:`WidthDeviations` (an ndarray (n,)) that says
    which times were compared and where each maximum is (``.describe()``)."""
    ta, tb = np.asarray(a.t, float), np.asarray(b.t, float)
    k = min(ta.size, tb.size)
    if k == 0 or not np.allclose(ta[:k], tb[:k], rtol=1e-12, atol=0):
        raise ValueError("the solutions do not share output times (run them with the same t0, t_end, output_dt)")
    wa, wb = a.hull[:k].width(), b.hull[:k].width()
    dev = np.abs(np.asarray(wa, float) - np.asarray(wb, float))  # (k, n)
    out = np.max(dev, axis=0).view(WidthDeviations)
    out.times = ta[:k]
    out.argmax_t = ta[np.argmax(dev, axis=0)]
    out.only_one = (ta if ta.size > tb.size else tb)[k:]
    out.state_names = tuple(getattr(a, "state_names", ()) or ())
    return out
