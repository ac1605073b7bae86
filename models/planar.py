"""n-link planar chains (all joints revolute about z, links along x).

Each link is a uniform rod of length ``l`` and mass ``m`` (centre of mass at the middle,
inertia m l^2 / 12 about the axes normal to the rod), or a point mass at its end
(``point_masses=True``).  Gravity (0, -g, 0): the base frame's y axis points up.
"""
from __future__ import annotations

from mbs import Chain, chain_from_dh


def _list(v, n, what):
    if isinstance(v, (int, float)) or hasattr(v, "free_symbols"):
        return [v] * n
    v = list(v)
    if len(v) != n:
        raise ValueError(f"{what}: expected {n} values, got {len(v)}")
    return v


def planar_chain(n, lengths=1.0, masses=1.0, *, point_masses=False, damping=0.0,
                 g=9.81, convention="standard", name=None) -> Chain:
    """An n-link planar chain as a DH table (standard or modified convention)."""
    ls, ms, ds = _list(lengths, n, "lengths"), _list(masses, n, "masses"), _list(damping, n, "damping")
    rows = []
    for i in range(n):
        l, m = ls[i], ms[i]
        if point_masses:
            inertia = None
            com_std, com_mod = (0, 0, 0), (l, 0, 0)
        else:
            inertia = (0.0, m * l * l / 12, m * l * l / 12)
            com_std, com_mod = (-l / 2, 0, 0), (l / 2, 0, 0)
        if convention == "standard":
            rows.append(dict(joint="R", a=l, mass=m, com=com_std, inertia=inertia, damping=ds[i]))
        else:
            # modified DH: row i carries a_{i-1}; link i's frame sits at joint i
            rows.append(dict(joint="R", a=ls[i - 1] if i else 0.0, mass=m, com=com_mod,
                             inertia=inertia, damping=ds[i]))
    return chain_from_dh(rows, convention=convention, gravity=(0.0, -g, 0.0),
                         name=name or f"planar{n}_{convention}")
