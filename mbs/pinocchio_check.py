"""Pinocchio as the referee: build a ``pin.Model`` for a chain and compare.

- From a URDF chain: Pinocchio's own parser (``pin.buildModelFromXML``), then
  ``pin.buildReducedModel`` for the locked joints -- an independent reading of the file.
- From any other chain (DH, hand-built): joint by joint from our tree
  (``JointModelRevoluteUnaligned`` / ``JointModelPrismaticUnaligned``).

Differences accounted for in :func:`compare_with_pinocchio`:

- Pinocchio's ``computePotentialEnergy`` leaves out the fixed base link; ours includes it
  (a constant ``NumericModel.base_potential``).
- ``aba``/``rnea`` ignore URDF damping; we pass ``tau - D qd``.
- Continuous joints have nq = 2 (cos, sin) in Pinocchio; we convert.
"""
from __future__ import annotations

import numpy as np

from .errors import ModelError


def _pin():
    try:
        import pinocchio as pin  # (pinocchio only for the comparison, not at import mbs)
    except ImportError as e:  # pragma: no cover
        raise ModelError("Pinocchio is not installed (pip install pin)") from e
    return pin


def to_pinocchio(chain, from_source=True):
    """Pinocchio model (fixed base) of ``chain``; gravity set to ``chain.gravity``."""
    pin = _pin()
    src = chain.source
    if from_source and src.get("kind") == "urdf":
        try:
            model = pin.buildModelFromXML(src["xml"])
        except (ValueError, RuntimeError) as e:
            raise ModelError(f"Pinocchio's URDF parser (urdfdom) rejects {chain.name!r}: {e} "
                             "(urdfdom is stricter, e.g. revolute joints need <limit>; "
                             "use to_pinocchio(chain, from_source=False))") from e
        locked = src.get("locked", {})
        if locked:
            q0 = pin.neutral(model)
            ids = []
            for name, val in locked.items():
                jid = model.getJointId(name)
                j = model.joints[jid]
                if j.nq == 1:
                    q0[j.idx_q] = val
                elif j.nq == 2:
                    q0[j.idx_q:j.idx_q + 2] = (np.cos(val), np.sin(val))
                ids.append(jid)
            model = pin.buildReducedModel(model, ids, q0)
    else:
        num = chain.numeric()
        model = pin.Model()
        model.name = chain.name
        ids = []
        for i, b in enumerate(chain.bodies):
            parent = 0 if num.parents[i] < 0 else ids[num.parents[i]]
            axis = np.array(num.axes[i], dtype=float)
            jm = (pin.JointModelRevoluteUnaligned(axis) if num.kinds[i] == "revolute"
                  else pin.JointModelPrismaticUnaligned(axis))
            R, p = num.placements[i]
            jid = model.addJoint(parent, jm, pin.SE3(np.array(R, float), np.array(p, float)),
                                 b.joint.name)
            model.appendBodyToJoint(jid, pin.Inertia(float(num.mass[i]), np.array(num.com[i], float),
                                                     np.array(num.I_c[i], float)), pin.SE3.Identity())
            ids.append(jid)
    model.gravity.linear = np.array([float(g) for g in chain.gravity])
    return model


class _QMap:
    """Maps our q/qd (chain order) to Pinocchio's q/v (by joint name)."""

    def __init__(self, chain, model):
        self.model = model
        self.nq, self.nv = model.nq, model.nv
        self.entries = []
        for i, name in enumerate(chain.joint_names):
            if not model.existJointName(name):
                raise ModelError(f"joint {name!r} is missing from the Pinocchio model")
            j = model.joints[model.getJointId(name)]
            if j.nv != 1:
                raise ModelError(f"joint {name!r} has nv={j.nv} in Pinocchio")
            self.entries.append((i, j.idx_q, j.nq, j.idx_v))
        if model.nv != chain.n:
            raise ModelError(f"Pinocchio model has nv={model.nv}, chain has {chain.n} dof")

    def q(self, q):
        out = np.zeros(self.nq)
        for i, iq, nq, _ in self.entries:
            if nq == 1:
                out[iq] = q[i]
            else:
                out[iq:iq + 2] = (np.cos(q[i]), np.sin(q[i]))
        return out

    def v(self, v):
        out = np.zeros(self.nv)
        for i, _, _, iv in self.entries:
            out[iv] = v[i]
        return out

    def back(self, v):
        """Pinocchio v-vector -> chain order."""
        return np.array([v[iv] for _, _, _, iv in self.entries])

    def back_matrix(self, M):
        idx = [iv for _, _, _, iv in self.entries]
        return M[np.ix_(idx, idx)]


def random_states(chain, n_states, seed):
    rng = np.random.default_rng(seed)
    n = chain.n
    kinds = [b.joint.kind for b in chain.bodies]
    out = []
    for _ in range(n_states):
        q = np.array([rng.uniform(-np.pi, np.pi) if k == "revolute" else rng.uniform(-0.2, 0.2)
                      for k in kinds])
        qd = rng.normal(size=n)
        tau = rng.normal(size=n)
        out.append((q, qd, tau))
    return out


def pinocchio_reference(chain, q, qd, tau, model=None, data=None):
    """Pinocchio's values at one state, in chain order: dict with oMi (world placements
    of the body frames as (R, p)), M, K, P (+ our base offset), g, qdd (damping added)."""
    pin = _pin()
    model = model or chain.to_pinocchio()
    data = data or model.createData()
    qm = _QMap(chain, model)
    pq, pv = qm.q(q), qm.v(qd)
    damping = np.array([float(d) for d in chain.damping])
    pin.forwardKinematics(model, data, pq, pv)
    oMi = []
    for name in chain.joint_names:
        T = data.oMi[model.getJointId(name)]
        oMi.append((T.rotation.copy(), T.translation.copy()))
    M = qm.back_matrix(pin.crba(model, data, pq).copy())
    M = np.triu(M) + np.triu(M, 1).T
    K = pin.computeKineticEnergy(model, data, pq, pv)
    P = pin.computePotentialEnergy(model, data, pq)
    g = qm.back(pin.computeGeneralizedGravity(model, data, pq).copy())
    qdd = qm.back(pin.aba(model, data, pq, pv, qm.v(tau - damping * qd)).copy())
    bias = qm.back(pin.nonLinearEffects(model, data, pq, pv).copy())
    return {"oMi": oMi, "M": M, "K": float(K), "P": float(P), "g": g, "qdd": qdd, "bias": bias}


def _rel(errs, scales, floor=0.0):
    s = max(max(scales) if scales else 0.0, floor)
    return float(max(errs) / s) if s > 0 else float(max(errs))


def compare_with_pinocchio(chain, n_states=10, seed=0, symbolic=True, numeric=True):
    """Compare our models with Pinocchio at ``n_states`` random states.

    Returns ``{"numeric": {...}, "symbolic": {...}}``, each mapping a quantity
    ("fk", "M", "K", "P", "g", "qdd") to the max relative error: max over states of
    ``|ours - pin|_inf`` divided by the largest ``|pin|_inf`` seen over the states (so an
    energy that crosses zero is still judged relative to its size), with floors for
    quantities that may vanish at every sample: 1 mm * total mass * |g| for P and g,
    1e-3 |g| for qdd, 1 m for positions.  P is compared after adding our fixed-base
    constant to Pinocchio's value.
    """
    model = chain.to_pinocchio()
    data = model.createData()
    states = random_states(chain, n_states, seed)
    refs = [pinocchio_reference(chain, q, qd, tau, model, data) for q, qd, tau in states]
    report = {}
    num = chain.numeric()
    gnorm = float(np.linalg.norm(np.array(num.gravity, float)))
    total_mass = float(sum(num.mass))
    # floors of the error scales (1 mm lever arm, 1e-3 |g|): a quantity that happens to
    # be ~0 at every sample (a gravity torque about a vertical axis) is not judged by
    # its round-off alone
    floors = {"fk": 1.0, "M": 0.0, "K": 0.0, "P": 1e-3 * total_mass * gnorm,
              "g": 1e-3 * total_mass * gnorm, "qdd": 1e-3 * gnorm}
    offset = num.base_potential
    evaluators = {}
    if numeric:
        def ev_num(q, qd, tau):
            fk = num.forward_kinematics(q)
            return {"fk": [(np.array(R, float), np.array(p, float)) for R, p in fk],
                    "M": np.asarray(num.mass_matrix(q), float),
                    "K": float(num.kinetic_energy(q, qd)), "P": float(num.potential_energy(q)),
                    "g": np.asarray(num.gravity_torque(q), float),
                    "qdd": np.asarray(num.acceleration(q, qd, tau), float)}
        evaluators["numeric"] = ev_num
    if symbolic:
        sym = chain.symbolic()
        f = sym.lambdified()
        def ev_sym(q, qd, tau):
            out = f(q, qd, tau)
            return out
        evaluators["symbolic"] = ev_sym
    for label, ev in evaluators.items():
        errs = {k: [] for k in ("fk", "M", "K", "P", "g", "qdd")}
        scales = {k: [] for k in errs}
        for (q, qd, tau), ref in zip(states, refs):
            ours = ev(q, qd, tau)
            e_fk = 0.0
            s_fk = 0.0
            for (R, p), (Rr, pr) in zip(ours["fk"], ref["oMi"]):
                e_fk = max(e_fk, np.abs(R - Rr).max(), np.abs(p - pr).max())
                s_fk = max(s_fk, 1.0, np.abs(pr).max())
            errs["fk"].append(e_fk); scales["fk"].append(s_fk)
            for k in ("M", "g", "qdd"):
                errs[k].append(np.abs(np.asarray(ours[k]) - ref[k]).max())
                scales[k].append(np.abs(ref[k]).max())
            errs["K"].append(abs(ours["K"] - ref["K"])); scales["K"].append(abs(ref["K"]))
            Pref = ref["P"] + offset
            errs["P"].append(abs(ours["P"] - Pref)); scales["P"].append(abs(Pref))
        report[label] = {k: _rel(errs[k], scales[k], floors[k]) for k in errs}
    return report


def max_error(report) -> float:
    return max(v for part in report.values() for v in part.values())


def format_report(reports: dict) -> str:
    """Markdown table of {model name: compare_with_pinocchio report} (max relative errors)."""
    keys = ("fk", "M", "K", "P", "g", "qdd")
    lines = ["| model | model kind | " + " | ".join(keys) + " |",
             "|---|---|" + "---|" * len(keys)]
    for name, rep in reports.items():
        for kind, errs in rep.items():
            lines.append(f"| {name} | {kind} | " + " | ".join(f"{errs[k]:.1e}" for k in keys) + " |")
    return "\n".join(lines)
