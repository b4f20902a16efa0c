"""A jitted function's traced program kept across processes (sim/trace_cache.py): a second ExportedJit with
the same key, arguments' shapes and code loads it instead of tracing and gives the same results; any
other key or shape traces anew; a damaged file is traced again."""

from __future__ import annotations

import pytest

jax = pytest.importorskip("jax")
pytest.importorskip("flatbuffers")
import jax.numpy as jnp  # noqa: E402

from bayessim_exp.sim.trace_cache import ExportedJit, code_fingerprint  # noqa: E402

BODY_RUNS = []


def step(state, scale):
    BODY_RUNS.append(1)  # runs once per trace, never when the program is loaded
    return {"x": state["x"] * scale + 1.0, "n": state["n"] + 1}, jnp.sum(state["x"])


def out_like(state, scale):
    return state, 0


def args(n=3):
    return {"x": jnp.arange(n, dtype=jnp.float32), "n": jnp.zeros((), jnp.int32)}, jnp.float32(2.0)


def test_a_program_is_traced_once_and_loaded_afterwards(tmp_path):
    BODY_RUNS.clear()
    first = ExportedJit(step, "step:1", tmp_path, out_like)
    expected = jax.jit(step)(*args())
    got = first(*args())
    assert first.traced == 1 and len(list(tmp_path.glob("*.jax_exported"))) == 1
    runs = len(BODY_RUNS)
    later = ExportedJit(step, "step:1", tmp_path, out_like)  # as a later process would
    again = later(*args())
    assert later.traced == 0 and len(BODY_RUNS) == runs
    for a, b, c in zip(jax.tree_util.tree_leaves(expected), jax.tree_util.tree_leaves(got),
                       jax.tree_util.tree_leaves(again)):
        assert jnp.array_equal(a, b) and jnp.array_equal(a, c)
    assert jax.tree_util.tree_structure(again) == jax.tree_util.tree_structure(expected)
    # another key (another model, settings or code) or other shapes: traced anew
    other = ExportedJit(step, "step:2", tmp_path, out_like)
    other(*args())
    later(*args(5))
    assert other.traced == 1 and later.traced == 1 and len(list(tmp_path.glob("*.jax_exported"))) == 3


def test_a_damaged_program_is_traced_again(tmp_path, caplog):
    ExportedJit(step, "step:1", tmp_path, out_like)(*args())
    (path,) = tmp_path.glob("*.jax_exported")
    path.write_bytes(b"not a program")
    again = ExportedJit(step, "step:1", tmp_path, out_like)
    assert float(again(*args())[1]) == 3.0 and again.traced == 1
    assert "unreadable" in caplog.text
    reloaded = ExportedJit(step, "step:1", tmp_path, out_like)
    reloaded(*args())
    assert reloaded.traced == 0  # the file was rewritten whole


def test_the_code_fingerprint_covers_code_loaded_from_outside_site_packages(tmp_path):
    import sys

    before = code_fingerprint()
    assert before == code_fingerprint()
    source = tmp_path / "a_plugin_task.py"
    source.write_text("SCALE = 1\n")
    module = type(sys)("a_plugin_task")
    module.__file__ = str(source)  # as a plugin's task module would be
    sys.modules["a_plugin_task"] = module
    try:
        loaded = code_fingerprint()
        source.write_text("SCALE = 2\n")  # an edited plugin
        assert len({before, loaded, code_fingerprint()}) == 3
    finally:
        del sys.modules["a_plugin_task"]
