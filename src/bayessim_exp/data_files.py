"""Files that are data, not code: posteriors, fitted models and run artifacts as tensors plus a JSON description.

A file is what torch.save writes of {"format": FORMAT, "description": <JSON text>, "tensors": {"t0": Tensor, ...}},
and it is read back with torch.load(weights_only=True), whose unpickler builds tensors and plain containers
only: a file that names any other Python callable (a pickled object whose __reduce__ runs code) is refused
before anything in it runs. The description holds the values themselves (JSON), each tensor as a reference
with its shape and dtype, and each object as {"$class": name, "fields": ...} with the name looked up in
DATA_CLASSES, an allow-list filled by @data_class next to the classes. An object's fields are its instance
attributes unless its class defines to_state() / from_state(fields) (what cannot be stored as data: a
closure, a network's conditioned distribution, is rebuilt from what can).

Files written before this format (whole objects pickled) load only with trusted=True, which unpickles them
(code in them runs); `X.load(path, trusted=True).save(path)` converts one.
"""

from __future__ import annotations

import dataclasses
import functools
import importlib
import io
import json
import pickle
from pathlib import Path
from typing import Any

import numpy as np
import torch

from .errors import DataFileError

FORMAT = "bayessim_exp.data/1"
DATA_CLASSES: dict[str, type] = {}
# the modules that declare data classes: imported before a file is read, so that the allow-list is complete
_DECLARING_MODULES = (
    "bayessim_exp.distributions.independent",
    "bayessim_exp.distributions.mixture",
    "bayessim_exp.distributions.probit",
    "bayessim_exp.distributions.restricted",
    "bayessim_exp.distributions.truncated_prior",
    "bayessim_exp.distributions.importance",
    "bayessim_exp.models.mdnn",
    "bayessim_exp.models.mdrff",
    "bayessim_exp.models.flow",
    "bayessim_exp.models.linear",
    "bayessim_exp.inference.bayessim.correction",
    "bayessim_exp.api",
)


def allowed_classes() -> dict[str, type]:
    """Every class a data file may hold, by name."""
    for module in _DECLARING_MODULES:
        importlib.import_module(module)
    return DATA_CLASSES


def data_class(cls: type) -> type:
    """Allow instances of `cls` in data files, under its class name."""
    if DATA_CLASSES.get(cls.__name__, cls) is not cls:
        raise ValueError(f"two data classes are named {cls.__name__}")
    DATA_CLASSES[cls.__name__] = cls
    return cls


def dumps(obj: Any) -> bytes:
    """The file's bytes for `obj`: tensors, numbers, strings, None, lists, tuples, dicts, numpy arrays and
    scalars, torch generators, and instances of DATA_CLASSES, nested."""
    tensors: dict[str, torch.Tensor] = {}
    description = {"value": _encode(obj, tensors),
                   "tensors": {k: {"shape": list(t.shape), "dtype": str(t.dtype)} for k, t in tensors.items()}}
    buffer = io.BytesIO()
    torch.save({"format": FORMAT, "description": json.dumps(description), "tensors": tensors}, buffer)
    return buffer.getvalue()


def same_data(a: Any, b: Any) -> bool:
    """Whether a and b are saved as the same data: one class, the same fields, equal tensors (an object and its
    copy read back from a file)."""
    tensors_a: dict[str, torch.Tensor] = {}
    tensors_b: dict[str, torch.Tensor] = {}
    try:
        if _encode(a, tensors_a) != _encode(b, tensors_b):
            return False
    except TypeError:  # not data: the same only as itself
        return a is b
    return all(t.dtype == tensors_b[k].dtype and torch.equal(t, tensors_b[k]) for k, t in tensors_a.items())


def save_state(obj: Any, path: str | Path) -> None:
    Path(path).write_bytes(dumps(obj))


def load_state(path: str | Path, trusted: bool = False, convert_hint: str = "") -> Any:
    """The object saved at `path`. A file in the old pickle format (or any pickle carrying code) is refused
    unless trusted=True; `convert_hint` names the call that converts one (in the error message)."""
    hint = convert_hint or "load it with trusted=True and save it again"
    allowed_classes()
    try:
        raw = torch.load(path, weights_only=True)
    except pickle.UnpicklingError as exc:
        if not trusted:
            raise DataFileError(
                f"{path} holds pickled Python objects, not data: loading it could run any code it contains, so it "
                f"is refused. If it is a file bayessim_exp wrote before the data format and you trust its source, "
                f"convert it once: {hint}") from exc
        return torch.load(path, weights_only=False)
    if not isinstance(raw, dict) or raw.get("format") != FORMAT:
        if trusted:
            return raw  # an old file that held only tensors and containers
        raise DataFileError(f"{path} is not a bayessim_exp data file ({FORMAT}); if it is an older bayessim_exp "
                            f"file and you trust its source, convert it once: {hint}")
    try:
        description = json.loads(raw["description"])
        tensors = raw["tensors"]
        _check_tensors(description["tensors"], tensors)
        return _decode(description["value"], tensors)
    except DataFileError as exc:
        raise DataFileError(f"{path}: {exc}") from None
    # RuntimeError: a model's state dict whose shapes differ from the ones its config builds
    except (KeyError, TypeError, ValueError, AttributeError, RuntimeError) as exc:
        raise DataFileError(f"{path}: the description does not match the data ({type(exc).__name__}: {exc}); "
                            "the file is damaged or was altered") from exc


def _check_tensors(described: dict, tensors: dict) -> None:
    if set(described) != set(tensors):
        raise DataFileError("the tensors differ from the ones the description lists; the file was altered")
    for name, t in tensors.items():
        if not isinstance(t, torch.Tensor) or list(t.shape) != described[name]["shape"] \
                or str(t.dtype) != described[name]["dtype"]:
            raise DataFileError(f"tensor {name} is not the {described[name]} the description says; the file was altered")


def _encode(value: Any, tensors: dict[str, torch.Tensor]) -> Any:
    if value is None or isinstance(value, (bool, int, float, str)):
        return value
    if isinstance(value, torch.Tensor):
        name = f"t{len(tensors)}"
        tensors[name] = value
        return {"$tensor": name}
    if isinstance(value, np.ndarray):
        return {"$ndarray": _encode(torch.from_numpy(value), tensors)}
    if isinstance(value, np.generic):
        return {"$numpy": value.dtype.str, "value": value.item()}
    if isinstance(value, torch.Generator):
        return {"$generator": _encode(value.get_state(), tensors)}
    if isinstance(value, (list, tuple)):
        items = [_encode(v, tensors) for v in value]
        return items if isinstance(value, list) else {"$tuple": items}
    if isinstance(value, dict):
        if all(isinstance(k, str) and not k.startswith("$") for k in value):
            return {k: _encode(v, tensors) for k, v in value.items()}
        return {"$items": [[_encode(k, tensors), _encode(v, tensors)] for k, v in value.items()]}
    cls = type(value)
    if DATA_CLASSES.get(cls.__name__) is not cls:
        raise TypeError(f"{cls.__module__}.{cls.__qualname__} is not a data class (bayessim_exp.data_files.data_class): "
                        "it cannot be saved as data")
    fields = value.to_state() if hasattr(cls, "to_state") else _attributes(value)
    return {"$class": cls.__name__, "fields": {k: _encode(v, tensors) for k, v in fields.items()}}


def _attributes(obj: Any) -> dict:
    if dataclasses.is_dataclass(obj):
        return {f.name: getattr(obj, f.name) for f in dataclasses.fields(obj)}
    # functools.cached_property values (Monte Carlo moments) are recomputed, not stored
    cached = {k for c in type(obj).__mro__ for k, v in vars(c).items() if isinstance(v, functools.cached_property)}
    return {k: v for k, v in vars(obj).items() if k not in cached}


def _decode(value: Any, tensors: dict[str, torch.Tensor]) -> Any:
    if isinstance(value, list):
        return [_decode(v, tensors) for v in value]
    if not isinstance(value, dict):
        return value
    if "$tensor" in value:
        return tensors[value["$tensor"]]
    if "$ndarray" in value:
        return _decode(value["$ndarray"], tensors).numpy()
    if "$numpy" in value:
        return np.dtype(value["$numpy"]).type(value["value"])
    if "$generator" in value:
        generator = torch.Generator()
        generator.set_state(_decode(value["$generator"], tensors))
        return generator
    if "$tuple" in value:
        return tuple(_decode(v, tensors) for v in value["$tuple"])
    if "$items" in value:
        return {_decode(k, tensors): _decode(v, tensors) for k, v in value["$items"]}
    if "$class" in value:
        name = value["$class"]
        if name not in DATA_CLASSES:
            raise DataFileError(f"the file names class {name!r}, which is not one a data file may hold "
                                f"(allowed: {', '.join(sorted(DATA_CLASSES))})")
        cls = DATA_CLASSES[name]
        fields = {k: _decode(v, tensors) for k, v in value["fields"].items()}
        if hasattr(cls, "from_state"):
            return cls.from_state(fields)
        if dataclasses.is_dataclass(cls):
            return cls(**fields)
        obj = cls.__new__(cls)  # the state as it was saved: constructors estimate normalisers by Monte Carlo
        obj.__dict__.update(fields)
        return obj
    return {k: _decode(v, tensors) for k, v in value.items()}
