"""Shared rules of the physical device profiles (eRob actuators, hub motors).

Rule: profiles are frozen data; every number is validated when a profile is built or overridden
from a config, and an override is recorded in the profile's ``sources``.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import replace
from types import MappingProxyType
from typing import Any, TypeVar

from joints.errors import ConfigError

P = TypeVar("P")


def validate_fields(obj: Any, ints: Iterable[str], floats: Iterable[str], non_negative: Iterable[str]) -> None:
    """Normalise and check a frozen profile's numbers in place (raises :class:`ConfigError`)."""
    model = obj.model
    if not isinstance(model, str) or not model.strip():
        raise ConfigError(f"expected a non-empty model name, got {model!r}", key="model")
    for name in ints:
        value = getattr(obj, name)
        if isinstance(value, float) and value.is_integer():
            value = int(value)
        if isinstance(value, bool) or not isinstance(value, int) or value <= 0:
            raise ConfigError(f"{model}: expected a positive integer, got {value!r}", key=name)
        object.__setattr__(obj, name, value)
    zero_ok = set(non_negative)
    for name in floats:
        value = getattr(obj, name)
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(f"{model}: expected a number, got {value!r}", key=name)
        value = float(value)
        low_ok = value >= 0.0 if name in zero_ok else value > 0.0
        if not (math.isfinite(value) and low_ok):
            need = "finite and >= 0" if name in zero_ok else "finite and > 0"
            raise ConfigError(f"{model}: expected {need}, got {value!r}", key=name)
        object.__setattr__(obj, name, value)


def with_overrides(obj: P, overridable: tuple[str, ...], kw: dict[str, object]) -> P:
    """A validated copy of ``obj`` with ``kw`` replaced; unknown keys list the allowed ones."""
    unknown = sorted(k for k in kw if k not in overridable)
    if unknown:
        raise ConfigError(
            f"{getattr(obj, 'model', '?')}: unknown profile key(s) {', '.join(map(repr, unknown))}",
            key=unknown[0],
            allowed=overridable,
        )
    if not kw:
        return obj
    sources = dict(getattr(obj, "sources"))  # noqa: B009
    for key in kw:
        sources[key] = f"CFG: overridden from config (default {getattr(obj, key)!r})"
    return replace(obj, sources=MappingProxyType(sources), **kw)  # type: ignore[type-var]
