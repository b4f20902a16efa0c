"""ParamSpec: named physical parameters bound to MuJoCo model fields, written per environment.

A parameter (IsaacGym-style) has a range (the prior's support), an operation and one or more targets; the
prior's family over the ranges is the `prior` config group's choice. A target names a model field and the entries it touches:

    body_mass[pole]            every entry of the row of body 'pole'
    body_inertia[pole,1]       one column of that row
    dof_damping[hinge]         the dofs of joint 'hinge'
    actuator_gainprm[*,0]      column 0 of every actuator; shell patterns (finger_*) work too
    opt.gravity[2]             an MjOption field

Operations, applied to the model's nominal values in this order: `set` (field = coef * v),
`scaling` (field *= (v / nominal) ** power; `nominal` is the physical value the MJCF was
written with, so parameters can be stated in physical units), `additive` (field += coef * v).
Several parameters may touch one field; their effects compose in that order.
"""

from __future__ import annotations

import dataclasses
import difflib
import fnmatch
import re
from collections.abc import Iterable
from typing import Any

import mujoco
import numpy as np

from ..errors import ConfigError

OPERATIONS = ("scaling", "additive", "set")
# model fields that mj_setConst reads (MuJoCo's engine_setconst.c): changing one per environment means
# recomputing the constants derived from it (subtree masses, inverse weights, actuator_acc0, ...)
SET_CONST_INPUTS = frozenset({
    "qpos0", "qpos_spring", "body_pos", "body_quat", "body_ipos", "body_iquat", "body_mass", "body_inertia",
    "body_gravcomp", "jnt_pos", "jnt_axis", "dof_armature", "geom_size", "geom_pos", "geom_quat", "geom_margin",
    "geom_gap", "site_pos", "site_quat", "tendon_stiffness", "tendon_damping", "tendon_armature", "wrap_prm",
    "actuator_gear", "actuator_cranklength", "actuator_damping", "actuator_armature", "eq_data",
})

# field prefix -> (object type, count attribute of MjModel)
_PREFIX_OBJECT = {
    "body_": (mujoco.mjtObj.mjOBJ_BODY, "nbody"),
    "jnt_": (mujoco.mjtObj.mjOBJ_JOINT, "njnt"),
    "dof_": (mujoco.mjtObj.mjOBJ_JOINT, "nv"),  # named by joint, indexed by dof
    "geom_": (mujoco.mjtObj.mjOBJ_GEOM, "ngeom"),
    "site_": (mujoco.mjtObj.mjOBJ_SITE, "nsite"),
    "actuator_": (mujoco.mjtObj.mjOBJ_ACTUATOR, "nu"),
    "tendon_": (mujoco.mjtObj.mjOBJ_TENDON, "ntendon"),
    "pair_": (mujoco.mjtObj.mjOBJ_PAIR, "npair"),
    "eq_": (mujoco.mjtObj.mjOBJ_EQUALITY, "neq"),
}
_TARGET_RE = re.compile(r"^\s*([A-Za-z_][\w.]*)\s*(?:\[([^\]]*)\])?\s*$")
_JOINT_DOFS = {
    mujoco.mjtJoint.mjJNT_FREE: 6,
    mujoco.mjtJoint.mjJNT_BALL: 3,
    mujoco.mjtJoint.mjJNT_SLIDE: 1,
    mujoco.mjtJoint.mjJNT_HINGE: 1,
}


@dataclasses.dataclass
class ParamConfig:
    """One parameter as written in a task YAML."""

    range: list[float]
    targets: list[Any]
    operation: str = "scaling"
    nominal: float = 1.0


def param_config(name: str, raw: Any) -> ParamConfig:
    """A task YAML's entry for parameter `name`, its keys checked."""
    if isinstance(raw, ParamConfig):
        return raw
    allowed = [f.name for f in dataclasses.fields(ParamConfig)]
    unknown = [k for k in raw if k not in allowed]
    if "distribution" in unknown:
        raise ConfigError(f"parameter {name!r}: 'distribution' is not a parameter key; the prior config group "
                          "chooses the family over every range (prior=uniform, loguniform or gaussian)")
    if unknown:
        raise ConfigError(f"parameter {name!r}: unknown keys {unknown}; allowed: {', '.join(allowed)}")
    return ParamConfig(**raw)


@dataclasses.dataclass(frozen=True)
class Target:
    field: str
    rows: np.ndarray | None  # object rows of the field, None for MjOption fields
    cols: np.ndarray | None  # columns within a row, None for all
    power: float = 1.0
    coef: float = 1.0

    def index(self, arr: np.ndarray) -> tuple:
        """Index into a per-simulation (n, ...) array of this field."""
        lead = (slice(None),)
        if self.rows is None:
            return lead + ((self.cols,) if self.cols is not None else ())
        if arr.ndim == 2:
            return lead + (self.rows,)
        if self.cols is None:
            return lead + (self.rows,)
        return lead + (self.rows[:, None], self.cols[None, :])


@dataclasses.dataclass(frozen=True)
class Param:
    name: str
    low: float
    high: float
    operation: str
    nominal: float
    targets: tuple[Target, ...]


class ParamSpec:
    """Ordered named parameters of a model; `apply` turns values [N, D] into model fields."""

    def __init__(self, params: list[Param]):
        if not params:
            raise ConfigError("a task must declare at least one parameter to infer")
        self.params = params
        self.names = [p.name for p in params]
        self.low = np.array([p.low for p in params])
        self.high = np.array([p.high for p in params])
        self.fields = sorted({t.field for p in params for t in p.targets})
        self.needs_set_const = any(f in SET_CONST_INPUTS or f.startswith("opt.") for f in self.fields)

    @property
    def dim(self) -> int:
        return len(self.params)

    @property
    def nominal(self) -> np.ndarray:
        """Nominal values [D]: the MJCF as written for scaling (`nominal`) and additive (0) parameters;
        the YAML's `nominal` for set parameters."""
        return np.array([nominal_value(p.operation, p.nominal) for p in self.params])

    @classmethod
    def from_config(cls, parameters: dict[str, Any], model: mujoco.MjModel) -> ParamSpec:
        params = []
        for name, raw in parameters.items():
            params.append(_parse_param(name, param_config(name, raw), model))
        return cls(params)

    def subset(self, names: Iterable[str]) -> ParamSpec:
        names = list(names)
        missing = [n for n in names if n not in self.names]
        if missing:
            raise ConfigError(_unknown("parameter", missing[0], self.names))
        return ParamSpec([p for p in self.params if p.name in names])

    def check_values(self, values: np.ndarray) -> np.ndarray:
        values = np.asarray(values, dtype=np.float64)
        if values.ndim != 2 or values.shape[1] != self.dim:
            raise ValueError(f"parameter values must be [N, {self.dim}] ({', '.join(self.names)}), got {values.shape}")
        return values

    def field_values(self, model: Any, values: Any, xp: Any = np) -> dict[str, Any]:
        """Per-environment values [N, ...] of every field the parameters touch. With xp=jax.numpy and a
        JAX model (the GPU backend's), the same operations run traceably (under jit) in the model leaves' dtypes."""
        values = self.check_values(values) if xp is np else values
        n = values.shape[0]
        out = {f: xp.repeat(_nominal(model, f, xp)[None], n, axis=0) for f in self.fields}
        for op in OPERATIONS[::-1]:  # set, scaling, additive
            for j, p in enumerate(self.params):
                if p.operation != op:
                    continue
                v = values[:, j]
                for t in p.targets:
                    arr = out[t.field]
                    idx = t.index(arr)
                    bshape = (n,) + (1,) * (arr[idx].ndim - 1)
                    if op == "set":
                        new = (t.coef * v).reshape(bshape)
                    elif op == "scaling":
                        new = arr[idx] * ((v / p.nominal) ** t.power).reshape(bshape)
                    else:
                        new = arr[idx] + (t.coef * v).reshape(bshape)
                    out[t.field] = _assign(arr, idx, new)
        return out


def nominal_value(operation: str, nominal: float) -> float:
    """The value of a parameter at which the model is the MJCF as written: 0 for additive ones."""
    return 0.0 if operation == "additive" else float(nominal)


def _model_fields(model: mujoco.MjModel) -> list[str]:
    arrays = [n for n in dir(model) if not n.startswith("_") and isinstance(getattr(model, n), np.ndarray)]
    return arrays + [f"opt.{n}" for n in dir(model.opt) if not n.startswith("_")]


def _is_model_field(model: mujoco.MjModel, field: str) -> bool:
    if field.startswith("opt."):
        return not field[4:].startswith("_") and hasattr(model.opt, field[4:])
    return not field.startswith("_") and isinstance(getattr(model, field, None), np.ndarray)


def model_field(model: Any, field: str) -> Any:
    """A field of an MjModel or a JAX model (the GPU backend's) by its spec name ('opt.<name>' for the MjOption fields)."""
    return getattr(model.opt, field[4:]) if field.startswith("opt.") else getattr(model, field)


def _nominal(model: Any, field: str, xp: Any = np) -> Any:
    if xp is not np:  # a JAX model: its leaves, in their dtypes
        return xp.atleast_1d(model_field(model, field))
    return np.atleast_1d(np.array(model_field(model, field), dtype=np.float64))


def _assign(arr: Any, idx: tuple, new: Any) -> Any:
    """arr with arr[idx] = new: in place for numpy, a functional update for JAX arrays."""
    if isinstance(arr, np.ndarray):
        arr[idx] = new
        return arr
    return arr.at[idx].set(new)


def _unknown(kind: str, name: str, valid: Iterable[str]) -> str:
    valid = sorted(valid)
    close = difflib.get_close_matches(name, valid, n=4, cutoff=0.5)
    hint = f"; closest valid: {', '.join(close)}" if close else ""
    return f"unknown {kind} {name!r}{hint}"


def _parse_param(name: str, cfg: ParamConfig, model: mujoco.MjModel) -> Param:
    where = f"parameter {name!r}"
    if cfg.operation not in OPERATIONS:
        raise ConfigError(f"{where}: operation {cfg.operation!r} not allowed; allowed: {', '.join(OPERATIONS)}")
    if len(cfg.range) != 2 or not cfg.range[0] < cfg.range[1]:
        raise ConfigError(f"{where}: range must be [low, high] with low < high, got {list(cfg.range)}")
    if cfg.operation == "scaling" and cfg.nominal <= 0:
        raise ConfigError(f"{where}: a scaling parameter needs nominal > 0, got {cfg.nominal}")
    if not cfg.targets:
        raise ConfigError(f"{where}: no targets")
    targets = tuple(_parse_target(where, t, model) for t in cfg.targets)
    return Param(name, float(cfg.range[0]), float(cfg.range[1]), cfg.operation, float(cfg.nominal),
                 targets)


def _parse_target(where: str, raw: Any, model: mujoco.MjModel) -> Target:
    extra: dict[str, float] = {}
    if isinstance(raw, dict) or hasattr(raw, "items"):
        raw = dict(raw)
        spec = raw.pop("field", None)
        unknown = set(raw) - {"power", "coef"}
        if spec is None or unknown:
            raise ConfigError(f"{where}: a target mapping has keys field, power, coef; got {sorted(raw) + ['field']}")
        extra = {k: float(v) for k, v in raw.items()}
    else:
        spec = raw
    m = _TARGET_RE.match(str(spec))
    if not m:
        raise ConfigError(f"{where}: cannot read target {spec!r}; write e.g. body_mass[pole] or geom_size[rod,1]")
    field, index = m.group(1), [s.strip() for s in m.group(2).split(",")] if m.group(2) else []
    if not _is_model_field(model, field):
        raise ConfigError(f"{where}: {_unknown('model field', field, _model_fields(model))}")
    template = _nominal(model, field)
    if field.startswith("opt."):
        if len(index) > 1:
            raise ConfigError(f"{where}: {field} takes at most one index, got {spec!r}")
        cols = _columns(where, spec, index[0] if index else None, template.shape[0])
        return Target(field, None, cols, **extra)
    prefix = next((p for p in _PREFIX_OBJECT if field.startswith(p)), None)
    if prefix is None:
        raise ConfigError(f"{where}: field {field!r} is not per-object; supported prefixes: {', '.join(_PREFIX_OBJECT)}, opt.")
    if not index:
        raise ConfigError(f"{where}: target {spec!r} needs an object name, e.g. {field}[name] or {field}[*]")
    rows = _rows(where, model, prefix, index[0])
    ncols = template.shape[1] if template.ndim == 2 else 1
    if len(index) > 2:
        raise ConfigError(f"{where}: target {spec!r} has more than two indices")
    cols = _columns(where, spec, index[1] if len(index) == 2 else None, ncols)
    if template.ndim == 1 and cols is not None:
        raise ConfigError(f"{where}: {field} has one value per object; drop the column in {spec!r}")
    return Target(field, rows, cols, **extra)


def _columns(where: str, spec: Any, col: str | None, ncols: int) -> np.ndarray | None:
    if col is None or col == "*":
        return None
    try:
        c = int(col)
    except ValueError:
        raise ConfigError(f"{where}: column {col!r} in {spec!r} must be an integer") from None
    if not 0 <= c < ncols:
        raise ConfigError(f"{where}: column {c} in {spec!r} is out of range 0..{ncols - 1}")
    return np.array([c])


def _rows(where: str, model: mujoco.MjModel, prefix: str, pattern: str) -> np.ndarray:
    obj, count_attr = _PREFIX_OBJECT[prefix]
    nobj = model.njnt if prefix == "dof_" else getattr(model, count_attr)
    names = [mujoco.mj_id2name(model, obj, i) or "" for i in range(nobj)]
    if any(ch in pattern for ch in "*?["):
        ids = [i for i, n in enumerate(names) if fnmatch.fnmatchcase(n, pattern)]
        if not ids:
            raise ConfigError(f"{where}: pattern {pattern!r} matches no {obj.name[6:].lower()}; names: {', '.join(n for n in names if n)}")
    else:
        if pattern not in names:
            raise ConfigError(f"{where}: {_unknown(obj.name[6:].lower(), pattern, [n for n in names if n])}")
        ids = [names.index(pattern)]
    if prefix != "dof_":
        return np.array(ids)
    dofs = [model.jnt_dofadr[j] + k for j in ids for k in range(_JOINT_DOFS[mujoco.mjtJoint(model.jnt_type[j])])]
    return np.array(dofs)
