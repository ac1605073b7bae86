# Long (760 lines) on purpose: the scene format's documentation (120 lines) and one checker per table.
"""Scene files: one TOML file describes a whole guaranteed simulation.

``python -m mbs simulate SCENE --out DIR`` reads a scene with :func:`load_scene`
(standard-library ``tomllib``), runs :func:`mbs.simulate.simulate` and writes
``DIR/result.json`` and the figures. A scene::

    name = "double pendulum, paper eq. (22)"     # optional: title in reports
    description = "..."                          # optional

    [model]                 # exactly one of name / urdf / dh
    name = "double_pendulum_paper"       # a ready model (models.registry.NAMES, plus
                                         # "pendulum_paper", "double_pendulum_paper",
                                         # and the aliases of mbs.robots.ALIASES: "panda")
    # urdf = "robots/arm.urdf"           # a URDF file, relative to the scene file, or
    # urdf = "example-robot-data:ur5"    # a robot shipped with example-robot-data
    # dh = [ {joint = "R", a = "l1", mass = "m1"}, {joint = "R", a = 1.0, mass = 1.0} ]
    # convention = "standard"            # dh only: "standard" or "modified"
    # lock = { wrist_3_joint = 0.0 }     # urdf/dh: weld joints at fixed positions
    # gravity = [0.0, 0.0, -9.81]        # urdf/dh: gravity in the base frame [m/s^2]

    [parameters]            # optional; numbers, expressions or [lo, hi] intervals
    m1 = 1.0                # DH entries may name a parameter ("l1"); numbers are
    l1 = [0.99, 1.01]       # substituted, intervals become uncertain parameters (PARAMs
                            # of the graphs, simulate(params=...)). The paper's models
                            # take m1, m2, l1, l2, g (pendulum_paper: m, l, g).
    mass_scale = [0.95, 1.05]             # every moving body's inertia times one factor
    damping = [0.04, 0.06]                # every joint's damping [N m s/rad], each its own
    # damping = { elbow_joint = [0.0, 0.1] }       # or per joint
    # mass = { forearm_link = [2.1, 2.4] }         # body masses [kg]
    # mass_scale = { upper_arm_link = [0.9, 1.1] } # per body
    [parameters.payload]    # a point mass fixed to a link (also [[parameters.payload]])
    link = "tool0"
    mass = [0.9, 1.1]       # [kg]
    com = [0, 0, [0.04, 0.06]]            # [m] in the link's frame (default 0)
    # (see mbs.uncertain for the meanings; URDF and ready chain models take only these
    # physical keys)

    [initial]               # the initial box, required: one entry per state, named
                            # by the model's state names (chains: q1..qn, qd1..qdn)
                            # or x1..x2n in state order (positions, then rates)
    x1 = ["0.99*3*pi/4", "1.01*3*pi/4"]   # [lo, hi]
    x2 = "-11*pi/20"                      # a point
    x3 = 0.43
    x4 = 0.67
    # or, in state order:  box = [[lo, hi], [lo, hi], ...]

    [simulation]
    t_end = 1.0             # required [s]
    output_dt = 0.1         # outputs at k * output_dt (one float product each) and t_end
    mode = "ii"             # "i" | "ii" | "iii" (paper sec. 5.2)
    frames = ["tool0"]      # chains: frames enclosed in result.json and frame_region.png
                            # (default: the end effector, tool0 / tool / the last link)

    [solver]                # passed to verified.solver.solve
    order = 12
    tol = 1e-10
    subdivision = [64, 1, 1, 1]   # per state (list in state order or {x1 = 64}), or one int
    param_subdivision = { "payload.mass" = 4 }   # or split uncertain parameters (one box)
    h_max = 0.05
    max_boxes = 4096
    energy_shell = true     # chains without control: hold the sets inside H <= hmax
    invariant_after = 1.0   # PD holding a pose: from 1 s on, every later time in one proof

    [control]               # optional: joint torques (modes i, ii; see mbs.control)
    type = "pd"             # "pd" or "computed_torque"
    kp = [100, 100]         # N m/rad per joint (or one number, or {joint = number}); or
    kd = [20, 20]           # bandwidth = 4.0 (rad/s) and damping_ratio = 1.0 instead:
                            # Kp = w^2 M(q_ref), Kd = 2 zeta w M(q_ref) (gains = "diagonal": diag M)
    q_ref = [0.5, -0.3]     # default: the centre of the initial q box
    gravity_compensation = true           # pd: add g(q) of the nominal model
    nominal = { mass_scale = 1.1 }        # the controller's model: point parameters
    [control.trajectory]    # instead of q_ref: rest-to-rest quintic (t_end <= duration)
    q_end = [1.0, 0.2]
    duration = 2.0
    [control.disturbance]   # constant unknown torques [N m]
    joint1 = [-0.1, 0.1]

    [consistency]           # the energy consistency test (modes ii and iii)
    test_interval = 0.1
    test_splits = 10
    split_strategy = "gradient"
    backward_depth = 0
    energy_rate = "unsimplified"  # mode iii: "unsimplified" | "simplified" (verified.consistency.energy_rate)

Numbers are enclosed rigorously, never rounded inward:

* An integer, or a float that is exactly a double (``2.5``), is taken as is.
* A float that is not a double (``0.43``) stands for its decimal literal (the
  shortest decimal that reads back as that float, i.e. what was written): it is
  replaced by the tightest pair of doubles enclosing that decimal (one ulp wide).
* A string is an exact expression of decimal numbers, ``pi``, ``+ - * /``, unary
  minus and parentheses, linear in ``pi`` (``"0.99*3*pi/4"``, ``"-11*pi/20"``,
  ``"43/100"``). It is evaluated exactly (rational + rational * pi) and enclosed by
  the two doubles around it.

A bad scene raises :class:`SceneError` whose message names the file and the key:
unknown keys, a missing or empty initial box, inverted intervals, NaN or infinite
numbers, an unknown model, an unreadable URDF, bad solver settings.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from fractions import Fraction
from pathlib import Path

try:  # Python >= 3.11
    import tomllib
except ModuleNotFoundError:  # pragma: no cover - Python 3.10
    import tomli as tomllib

import numpy as np

import models
from models.registry import NAMES, SYSTEMS
from verified.consistency.energy_rate import MODEL_RATES
from verified.arith.exact import ExpressionError, enclose_fraction, enclose_pi_multiple, parse_pi_expression
from verified.arith.interval import Interval

from ..dh import chain_from_dh
from ..urdf import chain_from_urdf
from ..control import ControlError, parse_control
from ..errors import ModelError
from ..modes import MODES, get_mode
from ..robots import ALIASES, ERD_PREFIX, PAPER_MODELS, system_names, urdf_path
from ..simulate import output_times as _times
from ..uncertain import PHYSICAL_KEYS, _PAYLOAD_KEYS

__all__ = ["Scene", "SceneError", "load_scene", "parse_scene", "enclose_number", "PAPER_MODELS",
           "MODES", "scene_dir"]


_TOP = {"name", "description", "model", "parameters", "initial", "simulation", "solver", "consistency", "control"}
_MODEL = {"name", "urdf", "dh", "convention", "lock", "gravity"}
_SIMULATION = {"t_end", "output_dt", "mode", "frames"}
# solver settings: name -> (type check, description)
_SOLVER = {"order": int, "tol": float, "subdivision": None, "h_max": float, "h_min": float,
           "max_boxes": int, "max_steps": int, "max_width": float, "adaptive": bool,
           "split_ratio": float, "error_basis": str, "wrap_target": float, "arithmetic": str,
           "set_order": int, "merge_slack": float, "param_subdivision": None, "absorb": bool,
           "params_per_state": int, "energy_shell": bool, "invariant_after": float, "set_step": str,
           "model_degree": int, "method": str, "target_ratio": float, "max_pieces": int}
_CONSISTENCY = {"test_interval": float, "test_splits": int, "split_strategy": str,
                "backward_depth": int, "energy_rate": str, "contract": str, "prune": bool}
_CONTRACTS = ("step", "test", "off")
_ENERGY_RATES = MODEL_RATES  # the scene's energy_rate: what simulate() takes (verified.consistency.energy_rate)


class SceneError(ValueError):
    """A scene file that cannot be used; the message names the file and the key."""


def scene_dir() -> Path:
    """The directory of the scenes shipped with the package (models/scenes)."""
    return Path(models.__file__).parent / "scenes"


# --------------------------------------------------------------------------- numbers
def enclose_number(value, where: str = "value") -> tuple[float, float]:
    """(lo, hi) doubles enclosing a scene number (see the module docstring)."""
    if isinstance(value, bool):
        raise SceneError(f"{where}: expected a number, got a boolean")
    try:
        if isinstance(value, int):
            return enclose_fraction(Fraction(value))
        if isinstance(value, float):
            if not math.isfinite(value):
                raise SceneError(f"{where}: {value!r} is not a finite number")
            return enclose_fraction(Fraction(repr(value)))
        if isinstance(value, str):
            try:
                a, b = parse_pi_expression(value)
            except ExpressionError as e:
                raise SceneError(f"{where}: {e}") from None
            return enclose_pi_multiple(a, b)
    except OverflowError:  # (a number beyond the largest double: 1e400, 10**400)
        shown = repr(value) if len(repr(value)) <= 30 else repr(value)[:24] + "..."
        raise SceneError(f"{where}: {shown} is too large for a double (at most about 1.8e308)") from None
    raise SceneError(f"{where}: expected a number, an expression string or [lo, hi], "
                     f"got {type(value).__name__}")


def _interval(value, where: str) -> tuple[float, float]:
    """(lo, hi) of a number, an expression or a [lo, hi] pair."""
    if isinstance(value, list):
        if len(value) != 2:
            raise SceneError(f"{where}: an interval is [lo, hi], got {len(value)} entries")
        lo = enclose_number(value[0], f"{where}[0]")[0]
        hi = enclose_number(value[1], f"{where}[1]")[1]
        if lo > hi:
            raise SceneError(f"{where}: inverted interval [{value[0]!r}, {value[1]!r}] (lo > hi)")
        return lo, hi
    return enclose_number(value, where)


def _number(value, where, kind=float, positive=False):
    ok = isinstance(value, (int, float)) and not isinstance(value, bool)
    if kind is int:
        ok = isinstance(value, int) and not isinstance(value, bool)
    if not ok:
        raise SceneError(f"{where}: expected {'an integer' if kind is int else 'a number'}, got {value!r}")
    if not math.isfinite(value):
        raise SceneError(f"{where}: {value!r} is not a finite number")
    if positive and not value > 0:
        raise SceneError(f"{where}: must be > 0, got {value!r}")
    return kind(value)


def _unknown(table: dict, allowed, where: str):
    extra = sorted(set(table) - set(allowed))
    if extra:
        raise SceneError(f"{where}: unknown key{'s' if len(extra) > 1 else ''} "
                         f"{', '.join(repr(k) for k in extra)}; allowed: {', '.join(sorted(allowed))}")


def _table(data, key, where, required=False):
    if key not in data:
        if required:
            raise SceneError(f"{where}: missing [{key}] table")
        return {}
    t = data[key]
    if not isinstance(t, dict):
        raise SceneError(f"{where}: [{key}] must be a table, got {type(t).__name__}")
    return t


# --------------------------------------------------------------------------- scene
@dataclass
class Scene:
    """A parsed, validated scene (see the module docstring).

    ``model`` is what :func:`mbs.simulate.simulate` accepts: a model name or an
    :class:`mbs.Chain` (built by :meth:`build_model`, lazily).
    """

    source: str                         # file path or "<string>"
    name: str
    description: str
    model_spec: dict                    # the [model] table (urdf resolved to a path)
    parameters: dict                    # name -> (lo, hi)
    initial: dict | list                # name -> (lo, hi), or list of (lo, hi) in state order
    t_end: float
    output_dt: float | None
    mode: str
    solver: dict = field(default_factory=dict)
    consistency: dict = field(default_factory=dict)
    physical: dict = field(default_factory=dict)   # payload / mass_scale / mass / damping (mbs.uncertain)
    control: object = None                         # the [control] table(s) (mbs.control.parse_control)
    frames: tuple = ()                             # [simulation] frames: enclosed frames (default: the tool)
    _model: object = field(default=None, repr=False)

    # ---------------------------------------------------------------- model
    @property
    def model_label(self) -> str:
        s = self.model_spec
        if "name" in s:
            return s["name"]
        if "urdf" in s:
            return f"urdf:{s['urdf']}"
        return f"dh:{len(s['dh'])} rows"

    def point_params(self) -> dict:
        return {k: lo for k, (lo, hi) in self.parameters.items() if lo == hi}

    def interval_params(self) -> dict:
        return {k: (lo, hi) for k, (lo, hi) in self.parameters.items() if lo != hi}

    def build_model(self):
        """The model argument for simulate: a name (str) or a Chain."""
        if self._model is None:
            self._model = _build_model(self)
        return self._model

    # ---------------------------------------------------------------- initial box
    def initial_box(self, state_names):
        """The initial box as an Interval (n,) in the order of ``state_names``."""
        names = tuple(state_names)
        where = f"{self.source}: [initial]"
        if isinstance(self.initial, list):
            if len(self.initial) != len(names):
                raise SceneError(f"{where}: box has {len(self.initial)} entries, the model has "
                                 f"{len(names)} states ({', '.join(names)})")
            pairs = list(self.initial)
        else:
            by_index = _by_state(self.initial, names, where)
            missing = [names[i] for i in range(len(names)) if i not in by_index]
            if missing:
                raise SceneError(f"{where}: missing initial value for {', '.join(map(repr, missing))} "
                                 f"(states: {', '.join(names)})")
            pairs = [by_index[i] for i in range(len(names))]
        lo = np.array([p[0] for p in pairs])
        hi = np.array([p[1] for p in pairs])
        return Interval(lo, hi)

    def subdivision_for(self, state_names):
        sub = self.solver.get("subdivision")
        if sub is None or isinstance(sub, int):
            return sub
        names = tuple(state_names)
        where = f"{self.source}: [solver] subdivision"
        if isinstance(sub, list):
            if len(sub) != len(names):
                raise SceneError(f"{where}: {len(sub)} entries for {len(names)} states ({', '.join(names)})")
            return list(sub)
        by_index = _by_state(sub, names, where)
        return [by_index.get(i, 1) for i in range(len(names))]

    def t_eval(self, t_end: float | None = None, output_dt: float | None = None):
        """Output times: exactly k * output_dt (decimal, rounded to nearest) for
        k = 1, 2, ... up to t_end, plus t_end itself."""
        return output_times(self.t_end if t_end is None else t_end,
                            self.output_dt if output_dt is None else output_dt)

    def simulate_kwargs(self, state_names=None) -> dict:
        """Keyword arguments of :func:`mbs.simulate.simulate` (besides model, x0, t_end)."""
        kw = dict(self.consistency)
        for k, v in self.solver.items():
            if k == "subdivision":
                v = self.subdivision_for(state_names) if state_names is not None else v
            kw[k] = v
        # Point parameters of DH tables are substituted into the chain; for named
        # models all parameters go to simulate, intervals always do.
        params = dict(self.point_params()) if "name" in self.model_spec else {}
        params.update(self.interval_params())
        params.update(self.physical)
        if params:
            kw["params"] = params
        if self.control is not None:
            kw["control"] = self.control
        kw["mode"] = self.mode
        return kw


def _by_state(table: dict, names, where) -> dict:
    """{state index: value} for a table keyed by state names or by x1..xn (state order)."""
    out = {}
    for key, v in table.items():
        if key in names:
            i = names.index(key)
        elif key.startswith("x") and key[1:].isdigit() and 1 <= int(key[1:]) <= len(names):
            i = int(key[1:]) - 1
        else:
            raise SceneError(f"{where}: unknown state {key!r}; the model's states are {', '.join(names)} "
                             f"(or x1..x{len(names)} in that order)")
        if i in out:
            raise SceneError(f"{where}: state {names[i]!r} given twice ({key!r})")
        out[i] = v
    return out


def output_times(t_end: float, output_dt: float | None) -> list:
    """The output times of a run: ``k * output_dt`` (one float product each, never
    accumulated) for k = 1, 2, ... up to t_end, plus t_end (see
    :func:`mbs.simulate.output_times`)."""
    return [float(t) for t in _times(0.0, float(t_end), output_dt)]


def _resolve_urdf(spec: str, base: Path | None, where: str) -> str:
    if spec.startswith(ERD_PREFIX):
        name = spec[len(ERD_PREFIX):]
        try:
            return str(urdf_path(name))
        except ModelError as e:
            raise SceneError(f"{where}: {e}") from None
    p = Path(spec)
    if not p.is_absolute() and base is not None:
        p = base / p
    if not p.is_file():
        raise SceneError(f"{where}: URDF file {str(p)!r} not found")
    try:
        with open(p, "rb") as fh:
            fh.read(1)
    except OSError as e:
        raise SceneError(f"{where}: cannot read URDF file {str(p)!r}: {e.strerror}") from None
    return str(p)


def _build_model(scene: Scene):
    spec = scene.model_spec
    where = f"{scene.source}: [model]"
    if "name" in spec:
        return spec["name"]
    try:
        if "urdf" in spec:
            chain = chain_from_urdf(spec["urdf"], lock=spec.get("lock"),
                                    **({"gravity": spec["gravity"]} if "gravity" in spec else {}))
            return chain
        import sympy  # (import here: sympy only for DH-table models)
        rows = []
        symbols = {}
        for i, row in enumerate(spec["dh"]):
            r = {}
            for k, v in row.items():
                if isinstance(v, str) and k not in ("joint", "name"):
                    if v not in scene.parameters:
                        raise SceneError(f"{where} dh row {i}: {k} = {v!r} names no parameter "
                                         f"(known: {', '.join(scene.parameters) or 'none'})")
                    v = symbols.setdefault(v, sympy.Symbol(v, real=True))
                r[k] = v
            rows.append(r)
        kw = {"convention": spec.get("convention", "standard")}
        if "gravity" in spec:
            kw["gravity"] = tuple(spec["gravity"])
        chain = chain_from_dh(rows, **kw)
        points = {symbols[k]: v for k, v in scene.point_params().items() if k in symbols}
        if points:
            chain = chain.subs(points)
        if spec.get("lock"):
            chain = chain.lock(spec["lock"])
        return chain
    except SceneError:
        raise
    except (ModelError, ValueError, TypeError, KeyError, OSError) as e:
        what = f"URDF {spec['urdf']!r}" if "urdf" in spec else "DH table"
        raise SceneError(f"{where}: cannot build the model from the {what}: {e}") from None
    except Exception as e:  # yourdfpy/lxml parse errors and the like
        what = f"URDF {spec['urdf']!r}" if "urdf" in spec else "DH table"
        raise SceneError(f"{where}: cannot build the model from the {what}: "
                         f"{type(e).__name__}: {e}") from None


def parse_scene(data: dict, source: str = "<string>", base: Path | None = None) -> Scene:
    """Validate a scene given as a dict (the parsed TOML); see :func:`load_scene`.
    Its tables are checked in this order, each by its own step."""
    _unknown(data, _TOP, source)
    name = data.get("name", Path(source).stem if source != "<string>" else "scene")
    description = data.get("description", "")
    if not isinstance(name, str) or not isinstance(description, str):
        raise SceneError(f"{source}: 'name' and 'description' must be strings")
    spec = _model_table(data, source, base)
    params, physical = _parameters(_table(data, "parameters", source), spec, f"{source}: [parameters]")
    initial = _initial_table(data, source)
    t_end, output_dt, frames, mode = _simulation_table(data, source)
    solver = _solver_table(data, source)
    cons = _consistency_table(data, source)
    control = _control_table(data, source, mode)
    scene = Scene(source=source, name=name, description=description, model_spec=spec,
                  parameters=params, physical=physical, initial=initial, t_end=t_end, output_dt=output_dt,
                  mode=mode, solver=solver, consistency=cons, control=control, frames=tuple(frames))
    if isinstance(initial, list) and isinstance(solver.get("subdivision"), list) \
            and len(solver["subdivision"]) != len(initial):
        raise SceneError(f"{source}: [solver] subdivision has {len(solver['subdivision'])} entries, "
                         f"the initial box {len(initial)}")
    return scene


def _model_table(data: dict, source: str, base) -> dict:
    """[model]: exactly one of name, urdf, dh, and what applies to it; the model spec."""
    where = f"{source}: [model]"
    model = _table(data, "model", source, required=True)
    _unknown(model, _MODEL, where)
    kinds = [k for k in ("name", "urdf", "dh") if k in model]
    if len(kinds) != 1:
        raise SceneError(f"{where}: give exactly one of name, urdf, dh (got "
                         f"{', '.join(kinds) or 'none'})")
    spec = dict(model)
    if "name" in model:
        known = tuple(NAMES) + system_names() + tuple(sorted(set(ALIASES) - set(NAMES)))
        if model["name"] not in known:
            nm = model["name"]
            hint = (f" (a URDF file or an example-robot-data model goes in urdf = {nm!r})"
                    if isinstance(nm, str) and (nm.startswith(ERD_PREFIX) or nm.lower().endswith((".urdf", ".xml")))
                    else "")
            raise SceneError(f"{where} name: unknown model {nm!r}{hint}; choose one of {', '.join(known)}")
        extra = [k for k in ("lock", "gravity", "convention") if k in model]
        if extra:
            raise SceneError(f"{where}: {', '.join(extra)} only apply to urdf and dh models")
    if "urdf" in model:
        if not isinstance(model["urdf"], str):
            raise SceneError(f"{where} urdf: expected a path string")
        spec["urdf"] = _resolve_urdf(model["urdf"], base, f"{where} urdf")
    if "dh" in model:
        rows = model["dh"]
        if not isinstance(rows, list) or not rows or not all(isinstance(r, dict) for r in rows):
            raise SceneError(f"{where} dh: expected a non-empty list of tables (one per joint)")
    elif "convention" in model:
        raise SceneError(f"{where} convention: only applies to dh models")
    if "lock" in model:
        if not isinstance(model["lock"], dict):
            raise SceneError(f"{where} lock: expected a table joint = position")
        spec["lock"] = {k: _number(v, f"{where} lock.{k}") for k, v in model["lock"].items()}
    if "gravity" in model:
        g = model["gravity"]
        if not isinstance(g, list) or len(g) != 3:
            raise SceneError(f"{where} gravity: expected [gx, gy, gz]")
        spec["gravity"] = [_number(v, f"{where} gravity[{i}]") for i, v in enumerate(g)]
    return spec


def _initial_table(data: dict, source: str):
    """[initial]: the initial box, a list (``box = [...]``) or {state: interval}."""
    where = f"{source}: [initial]"
    if "initial" not in data:
        raise SceneError(f"{source}: missing [initial] table (the initial box)")
    init = _table(data, "initial", source, required=True)
    if not init:
        raise SceneError(f"{where}: the initial box is empty; give [lo, hi] per state")
    if "box" in init:
        if len(init) > 1:
            raise SceneError(f"{where}: give either box = [...] or one entry per state, not both")
        box = init["box"]
        if not isinstance(box, list) or not box:
            raise SceneError(f"{where} box: expected a non-empty list of [lo, hi] (one per state)")
        initial = [_interval(v, f"{where} box[{i}]") for i, v in enumerate(box)]
    else:
        initial = {k: _interval(v, f"{where} {k}") for k, v in init.items()}
    return initial


def _simulation_table(data: dict, source: str):
    """[simulation]: ``(t_end, output_dt, frames, mode)``."""
    where = f"{source}: [simulation]"
    sim = _table(data, "simulation", source, required=True)
    _unknown(sim, _SIMULATION, where)
    if "t_end" not in sim:
        raise SceneError(f"{where}: missing t_end")
    t_end = _number(sim["t_end"], f"{where} t_end", positive=True)
    output_dt = sim.get("output_dt")
    if output_dt is not None:
        output_dt = _number(output_dt, f"{where} output_dt", positive=True)
    frames = sim.get("frames", [])
    if isinstance(frames, str):
        frames = [frames]
    if not isinstance(frames, list) or not all(isinstance(f, str) for f in frames):
        raise SceneError(f"{where} frames: expected a list of frame (link) names")
    mode = sim.get("mode", "ii")
    if mode not in MODES:
        raise SceneError(f"{where} mode: {mode!r} is not one of {', '.join(MODES)}")
    return t_end, output_dt, frames, mode


def _solver_table(data: dict, source: str) -> dict:
    """[solver]: the solver settings, the method made from them."""
    where = f"{source}: [solver]"
    solver = {}
    for k, v in _table(data, "solver", source).items():
        if k not in _SOLVER:
            _unknown({k: v}, _SOLVER, where)
        if k == "subdivision":
            solver[k] = _subdivision(v, f"{where} subdivision")
        elif k == "param_subdivision":
            if not isinstance(v, dict) or not all(isinstance(m, int) and not isinstance(m, bool) and m >= 1
                                                  for m in v.values()):
                raise SceneError(f"{where} param_subdivision: expected a table parameter = pieces (integers >= 1)")
            solver[k] = dict(v)
        else:
            solver[k] = _typed(v, _SOLVER[k], f"{where} {k}", positive=True)
    if "method" in solver:
        solver["method"] = _scene_method(solver, where)
    elif any(k in solver for k in ("target_ratio", "max_pieces")):
        # (the fields of method "auto", the default: a tightness goal and a budget of pieces)
        solver["method"] = _scene_method({"method": "auto", **solver}, where)
        for k in ("target_ratio", "max_pieces"):
            solver.pop(k, None)
    else:
        _scene_legacy_method(solver, where)
    return solver


def _consistency_table(data: dict, source: str) -> dict:
    """[consistency]: the energy test's settings."""
    where = f"{source}: [consistency]"
    cons = {}
    for k, v in _table(data, "consistency", source).items():
        if k not in _CONSISTENCY:
            _unknown({k: v}, _CONSISTENCY, where)
        cons[k] = _typed(v, _CONSISTENCY[k], f"{where} {k}", positive=(k != "backward_depth"))
    if cons.get("backward_depth", 0) < 0:
        raise SceneError(f"{where} backward_depth: must be >= 0")
    if "contract" in cons and cons["contract"] not in _CONTRACTS:
        raise SceneError(f"{where} contract: {cons['contract']!r} is not one of {', '.join(_CONTRACTS)}")
    if "energy_rate" in cons and cons["energy_rate"] not in _ENERGY_RATES:
        raise SceneError(f"{where} energy_rate: {cons['energy_rate']!r} is not one of "
                         f"{', '.join(_ENERGY_RATES)}")
    return cons


def _control_table(data: dict, source: str, mode: str):
    """[control]: its structure checked (joints and gains against the model when it
    runs), and only in modes i and ii; the table or None."""
    control = data.get("control")
    if control is not None:
        try:
            parse_control(control)   # structure now; joints and gains against the model when it runs
        except ControlError as e:
            raise SceneError(f"{source}: {e}") from None
        if get_mode(mode).symbolic:
            raise SceneError(f"{source}: [control] needs mode i or ii (the numeric model), not iii")
    return control


def _table_of_intervals(value, where: str, what: str) -> dict:
    if not isinstance(value, dict) or not value:
        raise SceneError(f"{where}: expected a table {what} = [lo, hi], got {value!r}")
    return {k: _interval(v, f"{where}.{k}") for k, v in value.items()}


def _payload(item, where: str) -> dict:
    if not isinstance(item, dict):
        raise SceneError(f"{where}: expected a table with link, mass and com, got {item!r}")
    allowed = tuple(k for k in _PAYLOAD_KEYS if k != "inertia")
    _unknown(item, allowed, where)
    for req in ("link", "mass"):
        if req not in item:
            raise SceneError(f"{where}: missing {req!r}")
    if not isinstance(item["link"], str):
        raise SceneError(f"{where} link: expected a link name, got {item['link']!r}")
    out = {"link": item["link"], "mass": _interval(item["mass"], f"{where} mass")}
    if out["mass"][0] < 0:
        raise SceneError(f"{where} mass: must be >= 0, got {item['mass']!r}")
    if "com" in item:
        com = item["com"]
        if not isinstance(com, list) or len(com) != 3:
            raise SceneError(f"{where} com: expected [x, y, z] (m, in the link's frame), got {com!r}")
        out["com"] = [_interval(v, f"{where} com[{i}]") for i, v in enumerate(com)]
    return out


def _parameters(table: dict, spec: dict, where: str):
    """[parameters]: (named parameters {name: (lo, hi)}, physical parameters in the
    form of :mod:`mbs.uncertain`, every number enclosed)."""
    params, physical = {}, {}
    for k, v in table.items():
        w = f"{where} {k}"
        if k == "payload":
            items = v if isinstance(v, list) else [v]
            if not items:
                raise SceneError(f"{w}: an empty list")
            pl = [_payload(item, w if len(items) == 1 else f"{w}[{i}]") for i, item in enumerate(items)]
            physical[k] = pl[0] if len(pl) == 1 else pl
        elif k in ("mass_scale", "damping"):
            physical[k] = _table_of_intervals(v, w, "body" if k == "mass_scale" else "joint") \
                if isinstance(v, dict) else _interval(v, w)
            vals = physical[k].values() if isinstance(physical[k], dict) else [physical[k]]
            for lo, _ in vals:
                if lo < 0 or (k == "mass_scale" and lo == 0):
                    raise SceneError(f"{w}: must be {'>' if k == 'mass_scale' else '>='} 0, got {v!r}")
        elif k == "mass":
            physical[k] = _table_of_intervals(v, w, "body")
            if any(lo < 0 for lo, _ in physical[k].values()):
                raise SceneError(f"{w}: masses must be >= 0, got {v!r}")
        else:
            if isinstance(v, dict):
                raise SceneError(f"{w}: expected a number or [lo, hi] (tables only for "
                                 f"{', '.join(PHYSICAL_KEYS)})")
            params[k] = _interval(v, w)
    if params:
        allowed = None
        if "urdf" in spec:
            allowed = ()
        elif spec.get("name") in system_names():
            allowed = tuple(SYSTEMS[spec["name"]].param_names)
        elif "name" in spec:
            allowed = ()
        if allowed is not None:
            bad = [k for k in params if k not in allowed]
            if bad:
                names = ", ".join(PHYSICAL_KEYS + allowed)
                raise SceneError(f"{where}: unknown parameter {bad[0]!r} for the model "
                                 f"{spec.get('name') or 'from ' + str(spec.get('urdf'))!r}; it takes {names}")
    return params, physical


def _typed(v, typ, where: str, positive: bool):
    """A scalar setting of type ``typ`` (bool, str, int or float), checked."""
    if typ is bool:
        if not isinstance(v, bool):
            raise SceneError(f"{where}: expected true or false, got {v!r}")
        return v
    if typ is str:
        if not isinstance(v, str):
            raise SceneError(f"{where}: expected a string, got {v!r}")
        return v
    return _number(v, where, typ, positive=positive)


def _scene_legacy_method(solver: dict, where: str) -> None:
    """The method settings of a scene without ``method`` (``order``, ``set_order``,
    ...: the old signature's selection of a method), checked by the method they
    describe (:func:`verified.methods.from_settings`); they stay in ``solver`` for
    :func:`mbs.simulate.simulate`, which runs that method as before."""
    from verified.methods import METHOD_FIELDS, from_settings
    given = {k: solver[k] for k in METHOD_FIELDS if k in solver}
    if not given:
        return
    try:
        from_settings(**given)
    except (TypeError, ValueError) as e:
        raise SceneError(f"{where} {e}") from None


def _scene_method(solver: dict, where: str):
    """``[solver] method = "..."`` and that method's fields (taken out of ``solver``),
    validated by the method (:mod:`verified.methods`)."""
    import dataclasses

    from verified.methods import METHOD_FIELDS, METHODS
    name = solver.pop("method")
    cls = METHODS.get(name)
    if cls is None:
        raise SceneError(f"{where} method: {name!r} is not one of {', '.join(METHODS)}")
    own = {f.name for f in dataclasses.fields(cls)}
    stray = sorted(k for k in solver if k in METHOD_FIELDS and k not in own)
    if stray:
        raise SceneError(f"{where} {stray[0]}: not a setting of method {name!r} (its settings: "
                         f"{', '.join(sorted(own - {'rungs'}))})")
    try:
        return cls(**{k: solver.pop(k) for k in list(solver) if k in own})
    except (TypeError, ValueError) as e:
        raise SceneError(f"{where} {e}") from None


def _subdivision(v, where):
    if isinstance(v, int) and not isinstance(v, bool):
        if v < 1:
            raise SceneError(f"{where}: must be >= 1")
        return v
    if isinstance(v, list):
        if not v or not all(isinstance(p, int) and not isinstance(p, bool) and p >= 1 for p in v):
            raise SceneError(f"{where}: expected a list of integers >= 1 (pieces per state)")
        return list(v)
    if isinstance(v, dict):
        if not all(isinstance(p, int) and not isinstance(p, bool) and p >= 1 for p in v.values()):
            raise SceneError(f"{where}: expected state = pieces (integers >= 1)")
        return dict(v)
    raise SceneError(f"{where}: expected an integer, a list or a table of pieces per state")


def load_scene(path) -> Scene:
    """Read and validate a TOML scene file (see the module docstring).

    ``path`` may also be the name of a shipped scene ("double_pendulum_paper").
    Raises :class:`SceneError` on any problem.
    """
    p = Path(path)
    if not p.exists() and not p.suffix:
        shipped = scene_dir() / f"{p.name}.toml"
        if shipped.is_file():
            p = shipped
    src = str(path)
    if not p.is_file():
        raise SceneError(f"{src}: scene file not found")
    try:
        with open(p, "rb") as fh:
            data = tomllib.load(fh)
    except tomllib.TOMLDecodeError as e:
        raise SceneError(f"{src}: not valid TOML: {e}") from None
    except OSError as e:
        raise SceneError(f"{src}: cannot read: {e.strerror}") from None
    return parse_scene(data, src, p.parent)


def loads_scene(text: str, base=None) -> Scene:
    """Parse a scene from a TOML string (relative URDF paths resolve against ``base``)."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise SceneError(f"<string>: not valid TOML: {e}") from None
    return parse_scene(data, "<string>", Path(base) if base else None)
