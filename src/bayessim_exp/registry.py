"""Registry of components: (group, name) -> factory, with typed, checked parameters.

Every option of a config group (task, prior, policy, summarizer, model, rl, sim, real) is a
factory registered under its name together with a dataclass of its parameters. `build`
checks a group's config against that dataclass (unknown keys and wrong types are errors that
list what is allowed) before calling the factory.

Built-in components are imported here, not by the entry module, so that any process that
builds a component (a submitit worker included) sees the full registry. Researchers add
their own with `register` in a module named in the top-level `plugins` list.
"""

from __future__ import annotations

import dataclasses
import difflib
import importlib
from collections.abc import Callable
from pathlib import Path
from typing import Any

from omegaconf import DictConfig, OmegaConf
from omegaconf.errors import OmegaConfBaseException

from .errors import ConfigError

CONF_DIR = Path(__file__).parent / "conf"  # the package's config (a link to conf/ in a source checkout)
GROUPS = ("task", "prior", "method", "policy", "summarizer", "model", "rl", "sim", "real")

_BUILTIN_MODULES = (
    "bayessim_exp.tasks.pendulum",
    "bayessim_exp.tasks.cartpole",
    "bayessim_exp.tasks.ant",
    "bayessim_exp.tasks.humanoid",
    "bayessim_exp.tasks.ball_balance",
    "bayessim_exp.tasks.ingenuity",
    "bayessim_exp.tasks.quadcopter",
    "bayessim_exp.tasks.shadow_hand",
    "bayessim_exp.tasks.anymal",
    "bayessim_exp.tasks.franka_cabinet",
    "bayessim_exp.tasks.mjcf",
    "bayessim_exp.priors",
    "bayessim_exp.policies",
    "bayessim_exp.summarizers.basic",
    "bayessim_exp.summarizers.correlation",
    "bayessim_exp.summarizers.signature",
    "bayessim_exp.summarizers.learned",
    "bayessim_exp.models.mdnn",
    "bayessim_exp.models.mdrff",
    "bayessim_exp.models.flow",
    "bayessim_exp.models.linear",
    "bayessim_exp.real",
    "bayessim_exp.recorded.lerobot",
    "bayessim_exp.recorded.csv_table",
    "bayessim_exp.inference.bayessim.method",
    "bayessim_exp.inference.simopt.method",
    "bayessim_exp.inference.sysid.method",
    "bayessim_exp.sim.native",
    "bayessim_exp.sim.mjx",
    "bayessim_exp.sim.auto",
    "bayessim_exp.rl.none",
    "bayessim_exp.rl.config",
)


@dataclasses.dataclass(frozen=True)
class Entry:
    factory: Callable[..., Any]
    params: type


_REGISTRY: dict[str, dict[str, Entry]] = {g: {} for g in GROUPS}
_loaded_builtins = False


def register(group: str, name: str, params: type) -> Callable[[Callable], Callable]:
    """Decorator: register `factory(params_instance, **deps)` as option `name` of `group`."""
    if group not in _REGISTRY:
        raise ConfigError(f"unknown config group {group!r}; groups are {sorted(_REGISTRY)}")
    if not dataclasses.is_dataclass(params):
        raise TypeError(f"params of {group}/{name} must be a dataclass, got {params!r}")

    def deco(factory: Callable) -> Callable:
        _REGISTRY[group][name] = Entry(factory, params)
        return factory

    return deco


def load_builtins() -> None:
    global _loaded_builtins
    if not _loaded_builtins:
        for module in _BUILTIN_MODULES:
            importlib.import_module(module)
        _loaded_builtins = True


def load_plugins(modules: list[str] | tuple[str, ...]) -> None:
    """Import researcher modules that register their own components."""
    for module in modules:
        try:
            importlib.import_module(module)
        except ImportError as exc:
            raise ConfigError(f"plugins: cannot import {module!r}: {exc}") from exc


def names(group: str) -> list[str]:
    load_builtins()
    return sorted(_REGISTRY[group])


def entry(group: str, name: str) -> Entry:
    load_builtins()
    options = _REGISTRY.get(group)
    if options is None:
        raise ConfigError(f"unknown config group {group!r}; groups are {sorted(_REGISTRY)}")
    if name not in options:
        close = difflib.get_close_matches(name, options, n=3)
        hint = f" (did you mean {', '.join(close)}?)" if close else ""
        raise ConfigError(
            f"{group}={name!r} is not a registered {group}{hint}; allowed: {', '.join(sorted(options))}"
        )
    return options[name]


def parse_params(group: str, cfg: DictConfig | dict) -> tuple[str, Any]:
    """Check a group's config against its option's dataclass; return (name, params)."""
    container = OmegaConf.to_container(cfg, resolve=True) if isinstance(cfg, DictConfig) else dict(cfg)
    if "name" not in container:
        raise ConfigError(f"{group}: config has no 'name' key; allowed names: {', '.join(names(group))}")
    name = container.pop("name")
    spec = entry(group, name).params
    # keys left out take the option's defaults from its YAML, the one place they are written
    container = {**{k: v for k, v in option_defaults(group, name).items() if k != "name"}, **container}
    allowed = [f.name for f in dataclasses.fields(spec)]
    unknown = [k for k in container if k not in allowed]
    if unknown:
        key = unknown[0]
        close = difflib.get_close_matches(key, allowed, n=3)
        hint = f" (did you mean {', '.join(close)}?)" if close else ""
        raise ConfigError(
            f"{group}.{key} is not a parameter of {group}={name}{hint}; allowed keys: {', '.join(allowed)}"
        )
    missing = [f.name for f in dataclasses.fields(spec) if f.name not in container
               and f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING]
    if missing:
        raise ConfigError(f"{group}={name} has no value for {', '.join(missing)}")
    try:
        typed = OmegaConf.merge(OmegaConf.structured(spec), container)
        params = OmegaConf.to_object(typed)
    except OmegaConfBaseException as exc:
        key = getattr(exc, "full_key", None) or "?"
        field = next((f for f in dataclasses.fields(spec) if f.name == str(key).split(".")[0]), None)
        want = _type_name(field.type) if field else "see the dataclass"
        raise ConfigError(
            f"{group}.{key}={getattr(exc, 'value', None)!r} is not allowed for {group}={name}: "
            f"expected {want}. ({exc.msg.splitlines()[0] if hasattr(exc, 'msg') and exc.msg else exc})"
        ) from None
    check = getattr(params, "validate", None)
    if check is not None:
        try:
            check()
        except ConfigError as exc:
            raise ConfigError(f"{group}={name}: {exc}") from None
    return name, params


def option_defaults(group: str, name: str) -> dict:
    """The defaults of a built-in option: its YAML under the package's conf/ (empty if it has none)."""
    path = CONF_DIR / group / f"{name}.yaml"
    if not path.is_file():
        return {}
    values = OmegaConf.to_container(OmegaConf.load(path), resolve=True)
    values.pop("defaults", None)
    return values


def build(group: str, cfg: DictConfig | dict, **deps: Any) -> Any:
    name, params = parse_params(group, cfg)
    return entry(group, name).factory(params, **deps)


def _type_name(tp: Any) -> str:
    return tp if isinstance(tp, str) else getattr(tp, "__name__", str(tp))
