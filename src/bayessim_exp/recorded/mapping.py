"""Which logged values are the task's observations and actions, in which units.

A log is described by its schema: feature name -> the labels of its elements (a CSV column is a feature of one
element). A source names one element: `feature` (a feature of one element), `feature.element` (by the element's
name) or `feature[i]` (by position). Each observation and each actuator of the task takes one source, given as
the source alone or as a mapping:

    theta_dot: observation.state.joint2_vel
    cos_theta: {from: observation.state.joint2_pos, unit: deg, offset: 3.14159, transform: cos}

value = raw * scale * unit + offset (offset in the task's units, after the conversion; unit deg turns degrees and
degrees per second into radians), then `transform`: cos or sin of that angle, or its time derivative (for a
velocity the log does not hold): rate, or angle_rate for an angle that wraps (unwrapped first). Observations and actuators left out are looked up by their own name.
Actions are actuator commands in the units of the task's control range (`actuator_ctrlrange`), mapped to
[-1, 1], unless the log declares them normalised already (actions_normalised).
"""

from __future__ import annotations

import dataclasses
import difflib
import math
import re

import numpy as np

from ..errors import ConfigError, DataError
from ..tasks.base import Task
from . import resample

UNITS = {"rad": 1.0, "deg": math.pi / 180}
TRANSFORMS = ("cos", "sin", "rate", "angle_rate")
ENTRY_KEYS = ("from", "scale", "offset", "unit", "transform")
SHOWN = 40  # sources listed in an error message

Schema = dict[str, tuple[str, ...]]


def labels(feature: str, elements: tuple[str, ...]) -> list[str]:
    """How each element of a feature is named in a source: `feature` when it has one unnamed element."""
    if elements == ("0",):
        return [feature]
    return [f"{feature}.{e}" if not e.isdigit() else f"{feature}[{e}]" for e in elements]


def element_labels(width: int, names: list[str] | None) -> tuple[str, ...]:
    """The labels of a feature's elements: its names when it has one per element, else the positions."""
    return tuple(str(n) for n in names) if names and len(names) == width else tuple(str(i) for i in range(width))


@dataclasses.dataclass(frozen=True)
class Source:
    feature: str
    index: int
    label: str


@dataclasses.dataclass(frozen=True)
class Entry:
    target: str  # the task's observation or actuator
    source: Source
    factor: float  # scale * unit
    offset: float
    transform: str | None

    def convert(self, raw: np.ndarray) -> np.ndarray:
        return raw * self.factor + self.offset


def _every(schema: Schema) -> list[str]:
    return [label for f, elements in schema.items() for label in labels(f, elements)]


def _known(where: str, schema: Schema) -> str:
    names = _every(schema)
    more = f" and {len(names) - SHOWN} more" if len(names) > SHOWN else ""
    return f"{where} holds {', '.join(names[:SHOWN])}{more}"


def resolve(text: str, schema: Schema, where: str, purpose: str) -> Source:
    """The element a source string names (ConfigError listing the sources there are and the closest one)."""
    indexed = re.fullmatch(r"(.+)\[(\d+)\]", text)
    candidates = [(indexed.group(1), indexed.group(2))] if indexed else []
    candidates += [(text, None)] + [(text[: len(f)], text[len(f) + 1:]) for f in schema if text.startswith(f + ".")]
    for feature, element in candidates:
        elements = schema.get(feature)
        if elements is None:
            continue
        if element is None:
            if len(elements) == 1:
                return Source(feature, 0, text)
            raise ConfigError(f"{purpose}: {text!r} has {len(elements)} elements; name one: "
                              f"{', '.join(labels(feature, elements))}")
        if element in elements:
            return Source(feature, elements.index(element), text)
        if element.isdigit() and int(element) < len(elements):
            return Source(feature, int(element), text)
    close = difflib.get_close_matches(text, _every(schema), n=1, cutoff=0.5)
    hint = f" (closest: {close[0]})" if close else ""
    raise ConfigError(f"{purpose}: {text!r} is not in the log{hint}; {_known(where, schema)}")


def _by_name(name: str, schema: Schema, action: bool, width: int, position: int) -> Source | None:
    """The source a target left out of the mapping takes: the element (or one-element feature) named like it,
    from an action feature for actuators and from the others for observations where both hold one; an actuator
    also takes its position in a feature named `action` as wide as the task's actions (LeRobot's layout)."""
    found = [Source(f, i, label) for f, elements in schema.items() for i, (e, label) in
             enumerate(zip(elements, labels(f, elements))) if e == name or (label == name and len(elements) == 1)]
    if len(found) > 1:
        found = [s for s in found if s.feature.startswith("action") == action] or found
    if len(found) == 1:
        return found[0]
    if action and not found and len(schema.get("action", ())) == width:
        return Source("action", position, labels("action", schema["action"])[position])
    return None


def _entry(target: str, value, schema: Schema, where: str, purpose: str, transforms: bool) -> Entry:
    spec = {"from": value} if isinstance(value, str) else dict(value)
    allowed = ENTRY_KEYS if transforms else ENTRY_KEYS[:-1]
    unknown = [k for k in spec if k not in allowed]
    if unknown or "from" not in spec:
        close = difflib.get_close_matches(unknown[0], allowed, n=1) if unknown else []
        raise ConfigError(f"{purpose}: {spec} needs 'from' and takes only {', '.join(allowed)}"
                          + (f" ({unknown[0]!r}: did you mean {close[0]}?)" if close else ""))
    unit = spec.get("unit", "rad")
    if unit not in UNITS:
        raise ConfigError(f"{purpose}: unit={unit!r}; allowed: {', '.join(UNITS)} (other units: scale)")
    transform = spec.get("transform")
    if transform is not None and transform not in TRANSFORMS:
        raise ConfigError(f"{purpose}: transform={transform!r}; allowed: {', '.join(TRANSFORMS)}")
    try:
        factor, offset = float(spec.get("scale", 1.0)) * UNITS[unit], float(spec.get("offset", 0.0))
    except (TypeError, ValueError):
        raise ConfigError(f"{purpose}: scale and offset must be numbers, got {spec}") from None
    return Entry(target, resolve(str(spec["from"]), schema, where, purpose), factor, offset, transform)


class Mapping:
    """The task's observations and actions as functions of a log's features, checked against its schema."""

    def __init__(self, observations: dict | None, actions: dict | None, actions_normalised: bool, task: Task,
                 schema: Schema, where: str):
        self.task, self.normalised = task, actions_normalised
        observations, actions = observations or {}, actions or {}  # null: every target by its own name
        actuators = list(task.action_names)
        self.obs = self._entries("observations", observations, task.obs_names, schema, where, action=False)
        self.actions = self._entries("actions", actions, actuators, schema, where, action=True)
        lo, hi = task.model.actuator_ctrlrange[task.actuators].T
        if not actions_normalised and (hi <= lo).any():
            raise ConfigError(f"{where}: actuators {[a for a, w in zip(actuators, hi - lo) if w <= 0]} of task "
                              f"{task.name} have no control range to map commands from; log normalised actions "
                              "and set real.actions_normalised=true")
        self._mid, self._half = (hi + lo) / 2, (hi - lo) / 2

    def _entries(self, key: str, given: dict, targets, schema: Schema, where: str, action: bool) -> list[Entry]:
        unknown = [k for k in given if k not in targets]
        if unknown:
            close = difflib.get_close_matches(str(unknown[0]), targets, n=1)
            hint = f" (did you mean {close[0]}?)" if close else ""
            raise ConfigError(f"real.{key}.{unknown[0]} is not one of task {self.task.name}'s {key}{hint}; "
                              f"they are {', '.join(targets)}")
        entries = []
        for position, target in enumerate(targets):
            purpose = f"real.{key}.{target}"
            if target in given:
                entries.append(_entry(target, given[target], schema, where, purpose, transforms=not action))
                continue
            source = _by_name(target, schema, action, len(targets), position)
            if source is None:
                elements = {e: label for f, es in schema.items() for e, label in zip(es, labels(f, es))}
                close = difflib.get_close_matches(target, elements, n=1, cutoff=0.5)
                hint = f" (closest: {elements[close[0]]})" if close else ""
                raise ConfigError(f"{purpose}: the log names no element {target!r}{hint}; map it, e.g. "
                                  f"real.{key}={{{target}: <source>}} or {{{target}: {{from: <source>, unit: deg, ...}}}} "
                                  f"(README.md, 'Real data from a robot'); {_known(where, schema)}")
            entries.append(Entry(target, source, 1.0, 0.0, None))
        return entries

    @property
    def features(self) -> list[str]:
        """The log's features the mapping reads."""
        return sorted({e.source.feature for e in self.obs + self.actions})

    def apply(self, times: np.ndarray, columns: dict[str, np.ndarray], where: str) -> tuple[np.ndarray, np.ndarray]:
        """One episode's features [N, width] at `times` -> states [T+1, S] and actions [T, A] at the control rate."""

        def raw(entry: Entry) -> np.ndarray:
            values = np.asarray(columns[entry.source.feature], float)[:, entry.source.index]
            bad = np.flatnonzero(~np.isfinite(values))
            if bad.size:
                raise DataError(f"{where}: {entry.source.label} (the task's {entry.target}) is {values[bad[0]]} "
                                f"at row {bad[0]} ({bad.size} such rows); drop or fill those frames")
            return values

        raws = [raw(e) for e in self.obs + self.actions]  # every value checked before the time stamps
        grid = resample.control_times(times, self.task.cfg.control_dt, where)
        states = []
        for e, values in zip(self.obs, raws):
            value = e.convert(values)
            if e.transform is not None and e.transform != "rate":  # an angle: no wrap interpolated or differentiated
                value = np.unwrap(value)
            if e.transform in ("rate", "angle_rate"):
                value = np.gradient(value, times)
            value = resample.interpolate(times, value, grid)
            states.append(getattr(np, e.transform)(value) if e.transform in ("cos", "sin") else value)
        actions = []
        for k, (e, values) in enumerate(zip(self.actions, raws[len(self.obs):])):
            value = e.convert(values)
            normalised = value if self.normalised else (value - self._mid[k]) / self._half[k]
            over = np.flatnonzero(np.abs(normalised) > 1 + 1e-6)
            if over.size:
                lo, hi = (-1.0, 1.0) if self.normalised else (self._mid[k] - self._half[k], self._mid[k] + self._half[k])
                unit = "declared normalised" if self.normalised else f"{self.task.name}'s control range"
                raise DataError(f"{where}: {e.source.label} (actuator {e.target}) gives {value[over[0]]:g} at row "
                                f"{over[0]}, outside [{lo:g}, {hi:g}] ({unit}); check its unit and scale, or "
                                "real.actions_normalised")
            actions.append(resample.hold_average(times, normalised, grid))
        return np.stack(states, -1), np.stack(actions, -1)
