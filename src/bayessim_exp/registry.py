"""Registry of components: (group, name) -> factory, with typed, checked parameters.

Every option of a config group (task, prior, method, policy, summarizer, model, rl, sim, real) is a
factory together with a dataclass of its parameters. `build` checks a group's config against that
dataclass (unknown keys and wrong types are errors that list what is allowed) before calling the
factory.

Built-in options are listed here by import path ("module:attribute") and imported on first use:
listing the options imports nothing, checking a config imports only its dataclass's module, and
building a component only its factory's module (a run without RL never loads torchrl). Because the
list is here, not filled by side effects of imports, any process (a submitit worker included)
sees every built-in option. Researchers add their own with `register` in a module named in the
top-level `plugins` list.
"""

from __future__ import annotations

import dataclasses
import difflib
import functools
import importlib
import typing
from collections.abc import Callable
from pathlib import Path
from typing import Any, Literal

from omegaconf import DictConfig, OmegaConf
from omegaconf.errors import OmegaConfBaseException

from .errors import ConfigError

CONF_DIR = Path(__file__).parent / "conf"  # the package's config (a link to conf/ in a source checkout)


@dataclasses.dataclass(frozen=True)
class Entry:
    factory: Callable[..., Any]
    params: type
    # methods: (RoundContext, prior) -> the distribution a finished round handed on, read from its artifacts alone,
    # so that api.load_run builds no simulator (None: the method has none)
    posterior: Callable[..., Any] | None = None


@dataclasses.dataclass(frozen=True)
class Builtin:
    """A built-in option by import path, "<module>:<attribute>" with the module relative to the package;
    `params` names the dataclass, which may live in a lighter module than the factory."""

    factory: str
    params: str
    posterior: str | None = None  # methods: Entry.posterior


def _same_module(module: str, factory: str, params: str, posterior: str | None = None) -> Builtin:
    return Builtin(f"{module}:{factory}", f"{module}:{params}", None if posterior is None else f"{module}:{posterior}")


# group -> option -> a built-in by import path, or the Entry that `register` gave (a plugin's)
_REGISTRY: dict[str, dict[str, Entry | Builtin]] = {
    "task": {
        "Pendulum": _same_module("tasks.pendulum", "Pendulum", "PendulumConfig"),
        "Cartpole": _same_module("tasks.cartpole", "Cartpole", "CartpoleConfig"),
        "Ant": _same_module("tasks.ant", "Ant", "AntConfig"),
        "Humanoid": _same_module("tasks.humanoid", "Humanoid", "HumanoidConfig"),
        "BallBalance": _same_module("tasks.ball_balance", "BallBalance", "BallBalanceConfig"),
        "Ingenuity": _same_module("tasks.ingenuity", "Ingenuity", "IngenuityConfig"),
        "Quadcopter": _same_module("tasks.quadcopter", "Quadcopter", "QuadcopterConfig"),
        "ShadowHand": _same_module("tasks.shadow_hand", "ShadowHand", "ShadowHandConfig"),
        "ShadowHand_more": _same_module("tasks.shadow_hand", "ShadowHandMore", "ShadowHandConfig"),
        "Anymal": _same_module("tasks.anymal", "Anymal", "AnymalConfig"),
        "FrankaCabinet": _same_module("tasks.franka_cabinet", "FrankaCabinet", "FrankaCabinetConfig"),
        "mjcf": _same_module("tasks.mjcf", "MjcfTask", "MjcfConfig"),
    },
    "prior": {
        "uniform": _same_module("priors", "uniform_prior", "UniformPriorConfig"),
        "loguniform": _same_module("priors", "loguniform_prior", "LogUniformPriorConfig"),
        "gaussian": _same_module("priors", "gaussian_prior", "GaussianPriorConfig"),
    },
    "method": {
        "bayessim": Builtin("inference.bayessim.method:bayessim", "inference.bayessim.method:BayesSimConfig",
                            "inference.bayessim.handed_on:handed_on"),
        "simopt": _same_module("inference.simopt.method", "simopt", "SimOptConfig", "searched"),
        "sysid": _same_module("inference.sysid.method", "sysid", "SysidConfig", "fitted"),
    },
    "policy": {
        "random": _same_module("policies", "random_policy", "RandomPolicyConfig"),
        "replay": _same_module("policies", "replay_policy", "ReplayPolicyConfig"),
        "fixed": _same_module("policies", "fixed_policy", "FixedPolicyConfig"),
        "rl": Builtin("rl.actor_policy:rl_policy", "policies:RLPolicyConfig"),
        "rl_randomized": Builtin("rl.actor_policy:rl_randomized_policy", "policies:RandomizedRLPolicyConfig"),
    },
    "summarizer": {
        "start": _same_module("summarizers.basic", "StartSummarizer", "StepsConfig"),
        "waypoints": _same_module("summarizers.basic", "WaypointsSummarizer", "StepsConfig"),
        "corr": _same_module("summarizers.correlation", "corr", "CorrelationConfig"),
        "corrdiff": _same_module("summarizers.correlation", "corrdiff", "CorrelationConfig"),
        "signatory": _same_module("summarizers.signature", "signatory", "SignatureConfig"),
        "learned": _same_module("summarizers.learned", "learned", "LearnedConfig"),
    },
    "model": {
        "mdnn": _same_module("models.mdnn", "mdnn", "MdnnConfig"),
        "mdrff": _same_module("models.mdrff", "mdrff", "MdrffConfig"),
        "flow": _same_module("models.flow", "flow", "FlowConfig"),
        "linear": _same_module("models.linear", "linear", "LinearConfig"),
    },
    "rl": {
        "none": _same_module("rl.none", "no_rl", "NoRLConfig"),
        "ppo": Builtin("rl.component:ppo_component", "rl.config:PPOComponentConfig"),  # torchrl only when built
    },
    "sim": {
        "native": _same_module("sim.native", "native_backend", "NativeConfig"),
        "mjx": _same_module("sim.mjx", "mjx_backend", "MjxConfig"),
        "auto": Builtin("sim.auto:auto_backend", "sim.mjx:MjxConfig"),
    },
    "real": {
        "surrogate": _same_module("real", "surrogate", "SurrogateConfig"),
        "file": _same_module("real", "from_file", "FileConfig"),
        "csv": _same_module("recorded.csv_table", "from_csv", "CsvConfig"),
        "lerobot": _same_module("recorded.lerobot", "from_lerobot", "LeRobotConfig"),
    },
}
GROUPS = tuple(_REGISTRY)


def register(group: str, name: str, params: type,
             posterior: Callable[..., Any] | None = None) -> Callable[[Callable], Callable]:
    """Decorator: register `factory(params_instance, **deps)` as option `name` of `group`; a method may give
    `posterior(ctx, prior)`, which reads a finished round's distribution back for api.load_run (Entry.posterior)."""
    if group not in _REGISTRY:
        raise ConfigError(f"unknown config group {group!r}; groups are {sorted(_REGISTRY)}")
    if not dataclasses.is_dataclass(params):
        raise TypeError(f"params of {group}/{name} must be a dataclass, got {params!r}")
    if posterior is not None and group != "method":
        raise TypeError(f"only a method reads a posterior back; {group}/{name} was given one")

    def deco(factory: Callable) -> Callable:
        _REGISTRY[group][name] = Entry(factory, params, posterior)
        return factory

    return deco


def load_plugins(modules: list[str] | tuple[str, ...]) -> None:
    """Import researcher modules that register their own components."""
    for module in modules:
        try:
            importlib.import_module(module)
        except ImportError as exc:
            raise ConfigError(f"plugins: cannot import {module!r}: {exc}") from exc


def names(group: str) -> list[str]:
    return sorted(_REGISTRY[group])


def entry(group: str, name: str) -> Entry:
    """The option's factory and parameter dataclass (imports its modules on first use)."""
    option = _option(group, name)
    if isinstance(option, Builtin):
        reader = None if option.posterior is None else _resolve(option.posterior)
        option = Entry(_resolve(option.factory), _resolve(option.params), reader)
    return option


def posterior_reader(method: str) -> Callable[..., Any]:
    """Method `method`'s Entry.posterior; imports the reader's module only (BayesSim's is apart from its method)."""
    option = _option("method", method)
    reader = option.posterior
    if reader is None:
        raise ConfigError(f"method={method} gives no reader of its posterior from a run's artifacts: register it "
                          "with registry.register('method', name, params, posterior=...)")
    return _resolve(reader) if isinstance(reader, str) else reader


def params_type(group: str, name: str) -> type:
    """The option's parameter dataclass, imported without the factory's module."""
    option = _option(group, name)
    return _resolve(option.params) if isinstance(option, Builtin) else option.params


def _option(group: str, name: str) -> Entry | Builtin:
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


def _resolve(path: str) -> Any:
    module, attribute = path.split(":")
    return getattr(importlib.import_module(f"{__package__}.{module}"), attribute)


def parse_params(group: str, cfg: DictConfig | dict) -> tuple[str, Any]:
    """Check a group's config against its option's dataclass; return (name, params)."""
    container = OmegaConf.to_container(cfg, resolve=True) if isinstance(cfg, DictConfig) else dict(cfg)
    if "name" not in container:
        raise ConfigError(f"{group}: config has no 'name' key; allowed names: {', '.join(names(group))}")
    name = container.pop("name")
    spec = params_type(group, name)
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
        typed = OmegaConf.merge(OmegaConf.structured(_schema(spec)), container)
        params = _typed_as(spec, OmegaConf.to_object(typed))
    except OmegaConfBaseException as exc:
        key = getattr(exc, "full_key", None) or "?"
        field = next((f for f in dataclasses.fields(spec) if f.name == str(key).split(".")[0]), None)
        want = _type_name(field.type) if field else "see the dataclass"
        raise ConfigError(
            f"{group}.{key}={getattr(exc, 'value', None)!r} is not allowed for {group}={name}: "
            f"expected {want}. ({exc.msg.splitlines()[0] if hasattr(exc, 'msg') and exc.msg else exc})"
        ) from None
    try:
        _check_choices(params)
        check = getattr(params, "validate", None)
        if check is not None:
            check()
    except ConfigError as exc:
        raise ConfigError(f"{group}={name}: {exc}") from None
    return name, params


def _choices(spec: type) -> dict[str, tuple]:
    """The fields of a parameters dataclass typed `Literal[...]`, with the values each allows."""
    hints = typing.get_type_hints(spec)
    return {f.name: typing.get_args(hints[f.name]) for f in dataclasses.fields(spec)
            if typing.get_origin(hints[f.name]) is Literal}


@functools.cache
def _schema(spec: type) -> type:
    """`spec` as OmegaConf can type it: its Literal fields as str (OmegaConf 2.3 refuses Literal; _check_choices checks
    them), nested dataclasses likewise."""
    hints = typing.get_type_hints(spec)
    fields, changed = [], False
    for f in dataclasses.fields(spec):
        tp = hints[f.name]
        if typing.get_origin(tp) is Literal:
            tp = str
        elif dataclasses.is_dataclass(tp):
            tp = _schema(tp)
        changed |= tp is not hints[f.name]
        default = ({"default": f.default} if f.default is not dataclasses.MISSING else
                   {"default_factory": f.default_factory} if f.default_factory is not dataclasses.MISSING else {})
        fields.append((f.name, tp, dataclasses.field(**default)))
    return dataclasses.make_dataclass(spec.__name__, fields) if changed else spec


def _typed_as(spec: type, typed: Any) -> Any:
    """OmegaConf's object of _schema(spec) as a `spec`."""
    if typed is None or type(typed) is spec:
        return typed
    hints = typing.get_type_hints(spec)
    return spec(**{f.name: _typed_as(hints[f.name], getattr(typed, f.name)) if dataclasses.is_dataclass(hints[f.name])
                   else getattr(typed, f.name) for f in dataclasses.fields(spec)})


def _check_choices(params: Any, prefix: str = "") -> None:
    """Every Literal field of a parameters dataclass (nested ones too) holds one of its values."""
    for key, allowed in _choices(type(params)).items():
        value = getattr(params, key)
        if value not in allowed:
            raise ConfigError(f"{prefix}{key}={value!r} not allowed; allowed: {', '.join(allowed)}")
    for f in dataclasses.fields(params):
        if dataclasses.is_dataclass(value := getattr(params, f.name)):
            _check_choices(value, f"{prefix}{f.name}.")


def option_defaults(group: str, name: str) -> dict:
    """The defaults of a built-in option: its YAML under the package's conf/ (empty if it has none), with the
    blocks it shares with other options (conf/model/training) merged where its defaults list names them."""
    path = CONF_DIR / group / f"{name}.yaml"
    if not path.is_file():
        return {}
    return OmegaConf.to_container(_with_blocks(path), resolve=True)


def _with_blocks(path: Path) -> DictConfig:
    """A YAML's values and, in Hydra's order (_self_ last unless placed), those of the entries of its defaults list
    within its own group: `<subgroup>@_here_: <option>` and a plain option beside it. Entries naming other groups
    are left to Hydra: they may name other groups' choices (${task})."""
    values = OmegaConf.load(path)
    defaults = OmegaConf.to_container(values.pop("defaults", OmegaConf.create([])))  # unresolved: ${task}
    merged = OmegaConf.create()
    for entry in defaults if "_self_" in defaults else [*defaults, "_self_"]:
        if entry == "_self_":
            merged = OmegaConf.merge(merged, values)
        elif isinstance(entry, str):
            merged = OmegaConf.merge(merged, _with_blocks(path.parent / f"{entry}.yaml"))
        else:
            ((key, option),) = entry.items()
            subgroup, _, package = key.partition("@")
            if package == "_here_" and " " not in subgroup and not subgroup.startswith("/"):
                merged = OmegaConf.merge(merged, _with_blocks(path.parent / subgroup / f"{option}.yaml"))
    return merged


def build(group: str, cfg: DictConfig | dict, **deps: Any) -> Any:
    return factory(group, cfg)(**deps)


def factory(group: str, cfg: DictConfig | dict) -> Callable[..., Any]:
    """The option's factory with its checked parameters bound: what builds the option many times (a model per
    round, a policy per stage) parses its config, and reads its YAML defaults, once."""
    name, params = parse_params(group, cfg)
    return functools.partial(entry(group, name).factory, params)


def _type_name(tp: Any) -> str:
    return tp if isinstance(tp, str) else getattr(tp, "__name__", str(tp))
