"""The paper's two models as registry entries: ``"pendulum_paper"`` (sec. 5.1) and
``"double_pendulum_paper"`` (sec. 5.2).

Each is a :class:`PaperModel`, a System factory that :func:`mbs.simulate.simulate`
finds through :func:`mbs.robots.system_entry` (``models.registry.SYSTEMS``) instead of
treating the names as special cases:

- :meth:`PaperModel.chain`: the DH chain (:func:`models.pendulum.chain`,
  :func:`models.double_pendulum.dh_chain`) that modes i and ii integrate through the
  numeric model, and that the M(q) > 0 checks use in every mode;
- :meth:`PaperModel.system`: in mode iii the hand-written eqs. (18)/(19) or (22)/(24)
  traced into graphs, ``dH/dt`` unsimplified (``grad H . f``, eq. (7)) or simplified to
  0 after proving it symbolically; ``None`` in modes i and ii (the chain's numeric model).
"""
from __future__ import annotations

import inspect
from dataclasses import dataclass
from types import ModuleType

from mbs.errors import ModelError
from mbs.system import System
from verified.graph import from_sympy, trace

from . import double_pendulum, pendulum

__all__ = ["PaperModel", "PENDULUM", "DOUBLE_PENDULUM"]


def _param_names(mod: ModuleType) -> list:
    """The parameters of a paper model's hand-written functions (m1, m2, l1, l2, g / m, l, g)."""
    return [k for k in inspect.signature(mod.rhs).parameters if k not in ("x", "p")]


@dataclass(frozen=True)
class PaperModel:
    """One of the paper's models: ``name`` and the module holding its hand-written
    ``rhs``, ``hamiltonian``, ``sympy_model`` and its chain factory ``chain_factory``
    (called with sympy symbols for uncertain parameters)."""

    name: str
    module: ModuleType
    chain_factory: str

    @property
    def param_names(self) -> list:
        """The paper's parameters of the hand-written model (the only ones mode iii takes)."""
        return _param_names(self.module)

    def chain(self, params: dict | None = None):
        """The chain of the model (DH); the paper's parameters named in ``params``
        become sympy symbols (PARAMs of the graphs, see :mod:`mbs.uncertain`)."""
        make = getattr(self.module, self.chain_factory)
        if not params:
            return make()
        import sympy  # here, not at the top: 0.4 s that the numeric modes never need
        kw = {k: sympy.Symbol(k, positive=True) for k in self.param_names if k in params}
        return make(**kw)

    def system(self, mode, energy_rate: str, cparams=None) -> System | None:
        """The hand-written System of mode iii (``mode.symbolic``), else ``None``: modes
        i and ii integrate :meth:`chain` through the numeric model. ``energy_rate``:
        "unsimplified" or "simplified" (:mod:`verified.consistency.energy_rate`; "simplified" is
        proved 0 here, so the System declares "zero"); ``cparams``: the
        :class:`mbs.uncertain.ChainParameters` of uncertain parameters, or None."""
        if not mode.symbolic:
            return None
        import sympy  # (see chain)
        if cparams is not None:
            return self._system_with_params(energy_rate, cparams)
        mod, name = self.module, self.name
        xs, f, H = mod.sympy_model()
        names = [str(s) for s in xs]
        rhs = trace(mod.rhs, len(xs), input_names=names, output_names=[f"d{s}" for s in names])
        energy = from_sympy([H], xs, output_names=["H"])
        rate_expr = sum(sympy.diff(H, x) * fx for x, fx in zip(xs, f))  # eq. (7), not simplified
        if energy_rate == "simplified":
            self._prove_conservative(len(xs))
            return System(name=name, rhs=rhs, energy=energy, energy_rate="zero",
                          description="paper's symbolic model, dH/dt simplified to 0")
        return System(name=name, rhs=rhs, energy=energy,
                      energy_rate=from_sympy([rate_expr], xs, output_names=["dHdt"]),
                      description="paper's symbolic model, dH/dt unsimplified (grad H . f)")

    def _system_with_params(self, energy_rate: str, cparams) -> System:
        """Mode iii with some of the paper's parameters uncertain: the hand-written
        equations traced with those parameters as PARAMs."""
        import sympy  # (see chain)
        mod, name = self.module, self.name
        pnames = list(cparams.names)
        extra = [k for k in pnames if k not in self.param_names]
        if extra:
            raise ValueError(f"{name}: mode iii takes only the paper's parameters "
                             f"({', '.join(self.param_names)}) as params, not {', '.join(extra)}; "
                             "use mode i or ii for payloads, mass scales and damping")
        xs = list(sympy.sympify(mod.sympy_model()[0]))
        names = [str(s) for s in xs]
        n = len(xs)
        rhs = trace(lambda x, p: mod.rhs(list(x), **dict(zip(pnames, p))), n, len(pnames), input_names=names,
                    param_names=pnames, output_names=[f"d{s}" for s in names])
        energy = trace(lambda x, p: [mod.hamiltonian(list(x), **dict(zip(pnames, p)))], n, len(pnames),
                       input_names=names, param_names=pnames, output_names=["H"])
        if energy_rate == "simplified":
            self._prove_conservative(n)
            return System(name=name, rhs=rhs, energy=energy, energy_rate="zero", params=cparams.as_dict(),
                          description="paper's symbolic model with parameters, dH/dt simplified to 0")
        syms = [sympy.Symbol(k, positive=True) for k in pnames]
        kw = dict(zip(pnames, syms))
        f, H = mod.rhs(xs, **kw), mod.hamiltonian(xs, **kw)
        rate_expr = sum(sympy.diff(H, x) * fx for x, fx in zip(xs, f))
        rate = from_sympy([rate_expr], xs, syms, output_names=["dHdt"])
        return System(name=name, rhs=rhs, energy=energy, energy_rate=rate, params=cparams.as_dict(),
                      description="paper's symbolic model with parameters, dH/dt unsimplified (grad H . f)")

    def _prove_conservative(self, n: int):
        """dH/dt = grad H . f simplifies to 0 with every parameter a free symbol, so it is
        0 for the float parameter values too (simplifying with the float values leaves
        rounding residues such as 7e-15 x3 sin x1)."""
        import sympy  # (see chain)
        mod = self.module
        xs = list(sympy.symbols(f"x1:{n + 1}", real=True))
        ps = {k: sympy.Symbol(k, positive=True) for k in self.param_names}  # m, l, g, ...
        f = mod.rhs(xs, **ps)
        H = mod.hamiltonian(xs, **ps)
        rate = sympy.simplify(sum(sympy.diff(H, x) * fx for x, fx in zip(xs, f)))
        if rate != 0:  # pragma: no cover - guards the claim that the paper's models are conservative
            raise ModelError(f"{mod.__name__}: dH/dt does not simplify to 0 ({rate})")


PENDULUM = PaperModel("pendulum_paper", pendulum, "chain")
DOUBLE_PENDULUM = PaperModel("double_pendulum_paper", double_pendulum, "dh_chain")
