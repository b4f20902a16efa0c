"""A task's model with parameter values written in: as an MjModel (rendering a policy, rl/video.py) and as MJCF
(an identified model for another simulator stack, `python -m bayessim_exp.export`).

Both write the values through ParamSpec.field_values, the operations the simulation backends apply. The MJCF is the
task's file with the changed fields copied back (MjSpec.copy_back), so it keeps the file's structure, names and
defaults; MuJoCo writes numbers with 6 significant digits.
"""

from __future__ import annotations

import copy
from pathlib import Path

import mujoco
import numpy as np

from ..errors import ConfigError
from .base import Task

# fields that are a body's inertial: in an MJCF they must be explicit to be written (not inferred from geoms)
_INERTIAL = frozenset({"body_mass", "body_inertia", "body_ipos", "body_iquat"})


def _write(model: mujoco.MjModel, values: dict[str, np.ndarray]) -> None:
    for name, v in values.items():
        owner, field = (model.opt, name[4:]) if name.startswith("opt.") else (model, name)
        getattr(owner, field)[...] = v[0].reshape(getattr(owner, field).shape)


def model_with_params(task: Task, params: np.ndarray) -> mujoco.MjModel:
    """A copy of the task's model with parameters [D] written into its fields (derived constants not recomputed:
    call mj_setConst where task.spec.needs_set_const)."""
    model = copy.deepcopy(task.model)
    _write(model, task.spec.field_values(task.model, np.asarray(params, dtype=np.float64)[None]))
    return model


def mjcf_with_params(task: Task, params: np.ndarray, comment: str = "") -> str:
    """The task's MJCF with parameters [D] written in, as text; `comment` goes at its top. Asset directories
    become absolute, so the file loads from anywhere."""
    path = Path(task.model_path)
    spec = mujoco.MjSpec.from_file(str(path))
    for attr, assets in (("meshdir", [*spec.meshes, *spec.hfields]), ("texturedir", spec.textures)):
        if assets and not Path(getattr(spec, attr)).is_absolute():
            setattr(spec, attr, str((path.parent / getattr(spec, attr)).resolve()))
    if _INERTIAL & set(task.spec.fields):
        _explicit_inertials(spec)
    model = spec.compile()
    for field in task.spec.fields:  # the file must compile to the task's model, or the values land elsewhere
        if not np.array_equal(_field(model, field), _field(task.model, field)):
            raise ConfigError(f"{path} does not compile to {task.name}'s model ({field} differs): "
                              "cannot write its parameters into the file")
    _write(model, task.spec.field_values(task.model, np.asarray(params, dtype=np.float64)[None]))
    spec.copy_back(model)
    spec.comment = comment.replace("--", "-")  # "--" may not appear in an XML comment
    return spec.to_xml()


def write_mjcf(task: Task, params: np.ndarray, path: str | Path, comment: str = "") -> Path:
    """mjcf_with_params written to `path`."""
    path = Path(path)
    path.write_text(mjcf_with_params(task, params, comment))
    return path


def _field(model: mujoco.MjModel, field: str) -> np.ndarray:
    return np.asarray(getattr(model.opt, field[4:]) if field.startswith("opt.") else getattr(model, field))


def _explicit_inertials(spec: mujoco.MjSpec) -> None:
    """Make every body's inertial explicit, as compiled now: copy_back cannot write a mass or inertia that the
    compiler infers from geoms."""
    if spec.compiler.inertiafromgeom == mujoco.mjtInertiaFromGeom.mjINERTIAFROMGEOM_TRUE:
        # 'true' overrides even explicit inertials: take the compiled ones, then let explicit ones count
        compiled = spec.compile()
        spec.compiler.inertiafromgeom = mujoco.mjtInertiaFromGeom.mjINERTIAFROMGEOM_AUTO
        for body in spec.bodies[1:]:
            i = body.id
            if compiled.body_mass[i] <= 0:
                continue
            body.mass, body.ipos, body.iquat = compiled.body_mass[i], compiled.body_ipos[i], compiled.body_iquat[i]
            body.inertia, body.fullinertia = compiled.body_inertia[i], np.full(6, np.nan)  # nan: diagonal given
            body.explicitinertial = True
        return
    for body in spec.bodies[1:]:
        if not body.explicitinertial:
            spec.adopt_inertial(body)
