"""Traced JAX programs kept across processes (`jax.export`), so that a later run skips tracing them.

JAX's persistent compilation cache keeps XLA's compiled programs, but each process still traces and
lowers the Python functions first: for MJX's reset (the derived constants and a forward pass, under
vmap) and the fused rollout, a large share of a short GPU run (docs/benchmarks.md). A function traced once is exported (serialized StableHLO) under a key, and a
later process with the same key calls the exported program instead of tracing.

The key holds everything a trace can depend on: the caller's description of what the function closes
over (MjxSimulator: the compiled model, the task's config, the simulator's settings), the arguments'
tree, shapes and dtypes, the versions of jax, jaxlib, mujoco and mujoco-mjx, and the source of every module loaded
from outside site-packages (this package, a plugin's tasks): editing any of them traces anew.
"""

from __future__ import annotations

import hashlib
import logging
import os
import sys
import sysconfig
from collections.abc import Callable
from importlib import metadata
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

log = logging.getLogger(__name__)
_PACKAGES = ("jax", "jaxlib", "mujoco", "mujoco-mjx")


def _library_roots() -> tuple[str, ...]:
    paths = sysconfig.get_paths()
    return tuple(os.path.realpath(paths[k]) for k in ("stdlib", "platstdlib", "purelib", "platlib"))


def code_fingerprint() -> str:
    """Versions of the libraries a trace runs, and the source of every loaded module outside them."""
    h = hashlib.sha1()
    for name in _PACKAGES:
        try:
            h.update(f"{name}={metadata.version(name)};".encode())
        except metadata.PackageNotFoundError:
            h.update(f"{name}=-;".encode())
    roots = _library_roots()
    files = set()
    for module in list(sys.modules.values()):
        path = getattr(module, "__file__", None)
        if path and os.path.isabs(path) and path.endswith(".py"):
            real = os.path.realpath(path)
            if not real.startswith(roots) and os.path.isfile(real):
                files.add(real)
    for path in sorted(files):
        h.update(path.encode())
        h.update(Path(path).read_bytes())
    return h.hexdigest()


class ExportedJit:
    """`jax.jit(fn)` whose traced program is kept in `directory` under `key` plus the arguments' signature.

    `out_like(*args)` gives a pytree with the structure of fn's result (its leaves' values do not
    matter): a program loaded from disk returns flat arrays, and this puts them back in their tree.
    Where exporting fails (an operation jax.export cannot serialize) fn stays an ordinary jit."""

    def __init__(self, fn: Callable, key: str, directory: str | Path, out_like: Callable):
        import jax

        self.jax, self.fn, self.key, self.out_like = jax, fn, key, out_like
        self.directory = Path(directory).expanduser()
        self._programs: dict[tuple, tuple[Callable, Any]] = {}  # signature -> (program, the result's tree)
        self.traced = 0  # programs traced by this process (the rest were loaded)

    def __call__(self, *args):
        tu = self.jax.tree_util
        flat, tree = tu.tree_flatten(args)
        signature = (tree, tuple((x.shape, str(x.dtype)) for x in flat))
        if signature not in self._programs:
            self._programs[signature] = (self._program(flat, tree), tu.tree_structure(self.out_like(*args)))
        program, out_tree = self._programs[signature]
        return tu.tree_unflatten(out_tree, program(*flat))

    def _program(self, flat: list, tree: Any) -> Callable:
        jax = self.jax
        # the leaves' paths, shapes and dtypes: the tree's static data (MJX's wrapped numpy arrays, whose
        # text differs between processes) comes from the model, which the caller's key holds
        paths = [jax.tree_util.keystr(p) for p, _ in jax.tree_util.tree_flatten_with_path(tree.unflatten(flat))[0]]
        leaves = [(p, x.shape, str(x.dtype)) for p, x in zip(paths, flat)]
        settings = (jax.default_backend(), jax.config.jax_enable_x64, jax.config.jax_default_matmul_precision)
        digest = hashlib.sha1(f"{self.key}|{leaves}|{settings}".encode()).hexdigest()
        path = self.directory / f"{digest}.jax_exported"
        if path.exists():
            try:
                return jax.jit(jax.export.deserialize(bytearray(path.read_bytes())).call)
            except Exception as exc:  # noqa: BLE001 - a damaged file is traced again and replaced
                log.warning("trace cache: %s unreadable (%s); tracing again", path, exc)

        def flat_fn(*leaves):
            return jax.tree_util.tree_leaves(self.fn(*jax.tree_util.tree_unflatten(tree, leaves)))

        self.traced += 1
        specs = [jax.ShapeDtypeStruct(x.shape, x.dtype) for x in flat]
        try:
            exported = jax.export.export(jax.jit(flat_fn))(*specs)
        except Exception as exc:  # noqa: BLE001 - the function still runs, traced in every process
            log.info("trace cache: %s cannot be exported (%s); it is traced in every run",
                     getattr(self.fn, "__name__", self.fn), str(exc).splitlines()[0])
            return jax.jit(flat_fn)
        try:
            self.directory.mkdir(parents=True, exist_ok=True)
            partial = path.with_suffix(f".{os.getpid()}.partial")
            partial.write_bytes(exported.serialize())
            partial.replace(path)  # whole files only: a run killed meanwhile leaves no truncated program
        except (OSError, ImportError) as exc:  # a read-only cache, no flatbuffers: this run goes on
            log.warning("trace cache: cannot keep %s in %s (%s)", getattr(self.fn, "__name__", self.fn),
                        self.directory, exc)
        return jax.jit(exported.call)


def model_bytes(model: mujoco.MjModel) -> bytes:
    """The compiled model as MuJoCo saves it (MJB): equal bytes, equal model, for cache keys."""
    out = np.empty(mujoco.mj_sizeModel(model), np.uint8)
    mujoco.mj_saveModel(model, None, out)
    return out.tobytes()


def program_key(model: mujoco.MjModel, described: str) -> str:
    """A key of ExportedJit's programs: the compiled model and the caller's description of the rest."""
    return hashlib.sha1(model_bytes(model) + described.encode()).hexdigest()
