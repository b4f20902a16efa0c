"""mj_setConst's derived constants on the device: a JAX port of the parts of MuJoCo's engine_setconst.c
(setFixed and set0) that give the constants a ParamSpec makes vary, built on MJX's own kinematics,
composite-rigid-body mass matrix and its factorisation at qpos0. One slot's model in, its constants out:
the simulator vmaps it over the slots being reset, so no parameter set goes through the host.

Covered: body_subtreemass, geom_aabb and geom_rbound (primitive geoms), dof_M0, body_invweight0,
dof_invweight0, tendon_invweight0, actuator_acc0, cam_poscom0 and light_poscom0. `host_reasons` names
the model features the port leaves out; the constants they touch stay with mujoco.batch's set_const.
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from mujoco.mjx._src import smooth, support

COVERED = frozenset({"body_subtreemass", "geom_aabb", "geom_rbound", "dof_M0", "body_invweight0", "dof_invweight0",
                     "tendon_invweight0", "actuator_acc0", "cam_poscom0", "light_poscom0"})
_INVERSE_WEIGHTS = ("body_invweight0", "dof_invweight0", "tendon_invweight0", "actuator_acc0")
# the primitive geoms whose bounds follow from geom_size alone; planes, height fields and meshes keep theirs
_PRIMITIVES = {int(t) for t in (mujoco.mjtGeom.mjGEOM_SPHERE, mujoco.mjtGeom.mjGEOM_CAPSULE,
                                mujoco.mjtGeom.mjGEOM_ELLIPSOID, mujoco.mjtGeom.mjGEOM_CYLINDER, mujoco.mjtGeom.mjGEOM_BOX)}


def host_reasons(m: mujoco.MjModel, names: list[str]) -> dict[str, str]:
    """Constants among `names` this port does not compute for `m`, each with the reason."""
    out = {n: "not in the JAX port of mj_setConst" for n in names if n not in COVERED}
    armature = "actuator armature enters MuJoCo's mass matrix and dof_M0, not MJX's"
    if m.nu and m.actuator_armature.any():
        out.update({n: armature for n in ("dof_M0", *_INVERSE_WEIGHTS) if n in names})
    if m.ntendon and m.tendon_armature.any():
        out.update({n: "tendon armature in the mass matrix" for n in _INVERSE_WEIGHTS if n in names})
    if (m.body_simple == 2).any():
        out.update({n: "bodies compiled as simple (body_simple=2) take 1/mass"
                    for n in ("body_invweight0", "dof_invweight0") if n in names})
    return out


class DeviceConstants:
    """The constants `names` of one slot's mjx.Model (call it under jax.vmap)."""

    def __init__(self, m: mujoco.MjModel, template: Any, names: list[str]):
        self.names, self.template = list(names), template  # template: an mjx.Data of the nominal model
        # body i's subtree mass is the sum over the bodies it is an ancestor of (or is)
        self._subtree = np.eye(m.nbody)
        for i in range(m.nbody - 1, 0, -1):
            self._subtree[m.body_parentid[i]] += self._subtree[i]
        self._primitive = np.array([g for g in range(m.ngeom) if m.geom_type[g] in _PRIMITIVES], int)
        self._kind = m.geom_type[self._primitive]
        # a free joint's translations average over its 3 translational dofs, its rotations and a ball's over 3
        self._dof_mean = np.zeros((m.nv, m.nv))
        for j in range(m.njnt):
            adr, kind = m.jnt_dofadr[j], m.jnt_type[j]
            groups = {int(mujoco.mjtJoint.mjJNT_FREE): [range(0, 3), range(3, 6)],
                      int(mujoco.mjtJoint.mjJNT_BALL): [range(0, 3)]}.get(int(kind), [range(0, 1)])
            for g in groups:
                idx = adr + np.array(g)
                self._dof_mean[np.ix_(idx, idx)] = 1.0 / len(idx)
        # bodies welded to the world (no dofs) have zero inverse weight, the world body included
        self._moving = np.array([m.body_dofnum[m.body_weldid[i]] > 0 for i in range(m.nbody)])
        mocap = np.flatnonzero(m.body_mocapid >= 0)
        self._mocap_bodies = mocap[np.argsort(m.body_mocapid[mocap])]
        # a camera's or light's position held fixed in its body, relative to its target's (or body's) subtree com
        self._views = {"cam_poscom0": (m.cam_bodyid, np.where(m.cam_targetbodyid >= 0, m.cam_targetbodyid, m.cam_bodyid),
                                       m.cam_pos),
                       "light_poscom0": (m.light_bodyid, np.where(m.light_targetbodyid >= 0, m.light_targetbodyid,
                                                                  m.light_bodyid), m.light_pos)}

    def __call__(self, mx: Any) -> dict[str, jax.Array]:
        want, out = set(self.names), {}
        if "body_subtreemass" in want:
            out["body_subtreemass"] = jnp.asarray(self._subtree, mx.body_mass.dtype) @ mx.body_mass
        if want & {"geom_aabb", "geom_rbound"}:
            out.update(self._geom_bounds(mx))
        if want - {"body_subtreemass", "geom_aabb", "geom_rbound"}:
            out.update(self._at_qpos0(mx, want))
        return {n: out[n].astype(getattr(mx, n).dtype) for n in self.names}

    def _geom_bounds(self, mx: Any) -> dict[str, jax.Array]:
        """setFixed's bounding box [center, half sizes] and sphere of the primitive geoms (others keep theirs)."""
        size, kind = mx.geom_size[self._primitive], self._kind
        r, h = size[:, 0], size[:, 1]
        sphere, capsule, cylinder = (kind == mujoco.mjtGeom.mjGEOM_SPHERE, kind == mujoco.mjtGeom.mjGEOM_CAPSULE,
                                     kind == mujoco.mjtGeom.mjGEOM_CYLINDER)
        half = jnp.select([sphere[:, None], capsule[:, None], cylinder[:, None]],
                          [jnp.stack([r, r, r], -1), jnp.stack([r, r, r + h], -1), jnp.stack([r, r, h], -1)], size)
        rbound = jnp.select([sphere, capsule, cylinder, kind == mujoco.mjtGeom.mjGEOM_ELLIPSOID],
                            [r, r + h, jnp.sqrt(r * r + h * h), size.max(-1)], jnp.linalg.norm(size, axis=-1))
        aabb = jnp.concatenate([jnp.zeros_like(half), half], -1)
        return {"geom_aabb": mx.geom_aabb.at[self._primitive].set(aabb),
                "geom_rbound": mx.geom_rbound.at[self._primitive].set(rbound)}

    def _at_qpos0(self, mx: Any, want: set[str]) -> dict[str, jax.Array]:
        """set0: kinematics, com positions, mass matrix and its factor at qpos0, then the inverse weights."""
        d = self.template.replace(qpos=mx.qpos0)
        if len(self._mocap_bodies):
            d = d.replace(mocap_pos=mx.body_pos[self._mocap_bodies], mocap_quat=mx.body_quat[self._mocap_bodies])
        d = smooth.com_pos(mx, smooth.kinematics(mx, d))
        if mx.ntendon:
            d = smooth.tendon(mx, d)
        d = smooth.factor_m(mx, smooth.crb(mx, d))
        out: dict[str, jax.Array] = {"dof_M0": jnp.diagonal(support.full_m(mx, d))}
        for name in want & set(self._views):
            body, ref, pos = self._views[name]
            xpos = d.xpos[body] + jnp.einsum("nij,nj->ni", d.xmat[body], pos)
            out[name] = xpos - d.subtree_com[ref]
        if not want & set(_INVERSE_WEIGHTS):
            return out
        # inv(M), column by column through MJX's factor (dense or sparse alike)
        minv = jax.vmap(lambda e: smooth.solve_m(mx, d, e))(jnp.eye(mx.nv, dtype=d.qpos.dtype))
        if "dof_invweight0" in want:
            out["dof_invweight0"] = jnp.asarray(self._dof_mean, minv.dtype) @ jnp.diagonal(minv)
        if "body_invweight0" in want:
            def body_diag(i):  # diagonal of J inv(M) J' for the body's com Jacobian (3 translations, 3 rotations)
                jacp, jacr = support.jac(mx, d, d.xipos[i], i)
                jac = jnp.concatenate([jacp, jacr], 1)
                return jnp.einsum("kr,kl,lr->r", jac, minv, jac)

            diag = jax.vmap(body_diag)(jnp.arange(mx.nbody))
            weights = jnp.stack([diag[:, :3].mean(-1), diag[:, 3:].mean(-1)], -1)
            out["body_invweight0"] = jnp.where(self._moving[:, None], weights, 0.0)
        if "tendon_invweight0" in want:
            ten_j = d._impl.ten_J
            out["tendon_invweight0"] = jnp.einsum("tk,kl,tl->t", ten_j, minv, ten_j)
        if "actuator_acc0" in want:  # acceleration from a unit force of each actuator
            moment = smooth.transmission(mx, d)._impl.actuator_moment
            out["actuator_acc0"] = jnp.linalg.norm(moment @ minv, axis=-1)
        return out
