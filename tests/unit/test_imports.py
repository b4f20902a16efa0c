"""What a process imports: a default run leaves out what costs a noticeable part of its start, checking a
config imports no factory, and no module imports itself back at import time."""

from __future__ import annotations

import ast
import dataclasses
import subprocess
import sys
from pathlib import Path

import pytest

import bayessim_exp
from bayessim_exp import registry
from bayessim_exp.errors import ConfigError


@pytest.mark.slow  # a fresh Python process importing torch: make test, not make test-fast
def test_a_pipeline_process_fits_a_model_and_checks_mismatch_without_dynamo_scipy_stats_or_jax():
    # torch._dynamo (torch.optim imports it: 1.7 s here, 5.4 s on the H100 host; models/adam.py);
    # scipy.stats 0.3 s on top of scipy.optimize (which the MDN's spread calibration needs);
    # JAX and MJX 1.7 s on the development machine, needed only where sim=mjx runs
    code = ("import sys, torch; from bayessim_exp import api, registry; import bayessim_exp.pipeline; "
            "from bayessim_exp.diagnostics.mismatch import summaries_outside; "
            "cfg = api.compose(['model.max_epochs=2']); "
            "m = registry.build('model', cfg.model, theta_dim=2, x_dim=3); "
            "m.fit(torch.randn(300, 2), torch.randn(300, 3), seed=0); "
            "out = summaries_outside(torch.zeros(1, 3), torch.randn(100, 3), torch.randn(10, 3)); "
            "print(out['p_value'], *(name in sys.modules for name in ('torch._dynamo', 'scipy.stats', 'jax')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["[1.0]", "False", "False", "False"]


@pytest.mark.slow  # a fresh Python process importing torch: make test, not make test-fast
def test_checking_every_groups_config_loads_neither_torchrl_nor_jax_nor_the_factories():
    # the registry lists built-in options by import path: checking a config imports only the modules of
    # the options' dataclasses (rl=ppo's lives apart from its torchrl component), building one its factory's
    code = ("import sys; from bayessim_exp import registry; "
            "listed = sum(len(registry.names(g)) for g in registry.GROUPS); "
            "after_listing = sorted(m for m in sys.modules if m.startswith('bayessim_exp.')); "
            "from bayessim_exp import api; cfg = api.compose(['rl=ppo', 'policy=rl_randomized']); "
            "[registry.parse_params(g, cfg[g]) for g in registry.GROUPS]; "
            "print(listed > 30, after_listing, *(name in sys.modules for name in "
            "('torchrl', 'jax', 'bayessim_exp.rl.component', 'bayessim_exp.rl.actor_policy')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["True", "['bayessim_exp.errors',", "'bayessim_exp.registry',", "'bayessim_exp.run_name']",
                                  "False", "False", "False", "False"]


def test_every_built_in_option_resolves_to_a_factory_and_a_dataclass():
    for group in registry.GROUPS:
        for name in registry.names(group):
            option = registry.entry(group, name)
            assert callable(option.factory) and dataclasses.is_dataclass(option.params), (group, name)


def test_an_unknown_option_names_the_allowed_ones_and_the_closest():
    with pytest.raises(ConfigError, match=r"task='Pendulm' is not a registered task \(did you mean Pendulum\?\); "
                                          r"allowed: .*Cartpole.*Pendulum"):
        registry.params_type("task", "Pendulm")


def _module_imports(name: str, path: Path, modules: set[str]) -> set[str]:
    """The package's modules that `name` imports when it is imported: its top-level import statements (not
    those in functions or under TYPE_CHECKING), each with the packages above the imported module."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found = set()
    for node in ast.parse(path.read_text()).body:
        if isinstance(node, ast.Import):
            targets = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                above = package.rsplit(".", node.level - 1)[0]
                base = f"{above}.{base}" if base else above
            targets = [base, *(f"{base}.{alias.name}" for alias in node.names)]  # `from pkg import module`
        else:
            continue
        for target in targets:
            while target.startswith("bayessim_exp"):
                if target in modules and target != name:
                    found.add(target)
                target = target.rpartition(".")[0]
    return found


def _cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One cycle of the directed graph, or None."""
    state: dict[str, str] = {}  # visiting | done

    def visit(node: str, path: list[str]) -> list[str] | None:
        state[node] = "visiting"
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == "visiting":
                return [*path[path.index(nxt):], nxt]
            if nxt not in state and (found := visit(nxt, [*path, nxt])):
                return found
        state[node] = "done"
        return None

    for start in sorted(graph):
        if start not in state and (found := visit(start, [start])):
            return found
    return None


def test_no_module_imports_itself_back_at_import_time():
    src = Path(bayessim_exp.__file__).parent
    paths = {}
    for path in src.rglob("*.py"):
        parts = ("bayessim_exp", *path.relative_to(src).with_suffix("").parts)
        paths[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    graph = {name: _module_imports(name, path, set(paths)) for name, path in paths.items()}
    assert "bayessim_exp.rl.config" in graph["bayessim_exp.rl.component"]  # the parser sees relative imports
    assert _cycle(graph) is None, " -> ".join(_cycle(graph))


def test_no_subpackage_imports_itself_back_through_another():
    """Subpackages (sim, tasks, models, diagnostics, ...) import each other one way only; a top-level module
    (registry, pipeline, ...) counts as a node of its own."""
    src = Path(bayessim_exp.__file__).parent
    paths = {}
    for path in src.rglob("*.py"):
        parts = ("bayessim_exp", *path.relative_to(src).with_suffix("").parts)
        paths[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path

    def node(module: str) -> str:
        return ".".join(module.split(".")[:2])  # bayessim_exp.<subpackage or top-level module>

    graph: dict[str, set[str]] = {}
    for name, path in paths.items():
        graph.setdefault(node(name), set()).update(
            node(target) for target in _module_imports(name, path, set(paths)) if node(target) != node(name))
    assert "bayessim_exp.distributions" in graph["bayessim_exp.models"]
    assert _cycle(graph) is None, " -> ".join(_cycle(graph))
