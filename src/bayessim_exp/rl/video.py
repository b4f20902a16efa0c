"""A short GIF of a policy on fixed parameters, drawn with MuJoCo's offscreen renderer.

Rendering needs an MjData, so the episode is replayed here on one plain MuJoCo model with the
parameters written in (tasks/parameterized.py: the same ParamSpec.field_values the backends use),
whatever backend trained the policy. Headless machines need MUJOCO_GL=egl or osmesa set before mujoco is imported; without a GL
context `render_gif` returns None and the reason, and the run goes on. It does not even try GLFW
without a display: a second failed GLFW start aborts the whole process.
"""

from __future__ import annotations

import io
import os
import types

import mujoco
import numpy as np
import torch

from ..tasks.base import Task
from ..tasks.parameterized import model_with_params

_failed: list[str] = []  # the first failure's reason: a GL context that failed once is not tried again


def gl_unavailable() -> str:
    """Why no offscreen GL context can be made here ("" if one may be)."""
    if _failed:
        return _failed[0]
    if os.environ.get("MUJOCO_GL", "").lower() in ("egl", "osmesa") or os.environ.get("DISPLAY"):
        return ""
    return "no display and MUJOCO_GL is not egl or osmesa (set it before starting Python)"


def render_gif(task: Task, params: np.ndarray, policy, steps: int, size: int, seed: int) -> tuple[bytes | None, str]:
    """(GIF bytes, "") of `steps` control steps of `policy`, or (None, why not)."""
    from PIL import Image

    if gl_unavailable():
        return None, gl_unavailable()
    model = model_with_params(task, params)
    data = mujoco.MjData(model)
    if task.spec.needs_set_const:
        mujoco.mj_setConst(model, data)
    try:
        renderer = mujoco.Renderer(model, size, size)
    except Exception as exc:  # no EGL/OSMesa/GLX context: each backend raises its own type
        _failed.append(f"no OpenGL context for the offscreen renderer ({type(exc).__name__}: {exc})")
        return None, _failed[0]
    for field, values in task.reset_state(np.random.default_rng(seed), 1).items():
        getattr(data, field)[...] = values[0]
    mujoco.mj_forward(model, data)
    frames = []
    for t in range(steps):
        obs = task.observe(types.SimpleNamespace(**{f: getattr(data, f)[None] for f in task.data_fields}))
        action = policy.act(torch.as_tensor(np.asarray(obs), dtype=torch.float32), t)
        data.ctrl[:] = task.ctrl(action[0].numpy().astype(np.float64))
        mujoco.mj_step(model, data, nstep=task.frame_skip)
        renderer.update_scene(data)
        frames.append(Image.fromarray(renderer.render()))
    renderer.close()
    buffer = io.BytesIO()
    frames[0].save(buffer, format="GIF", save_all=True, append_images=frames[1:], loop=0,
                   duration=int(1000 * task.cfg.control_dt))
    return buffer.getvalue(), ""
