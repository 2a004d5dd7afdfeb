"""Writing TOML: what ``params dump`` and ``sim serve --hardware-config`` produce (tomllib only reads).

Rule: the subset a config or a parameter dump needs - tables, sub-tables, strings, integers,
finite floats, booleans and arrays of those; inline tables become sub-tables. Keys that are not
bare words are quoted. Output round-trips through :mod:`tomllib` to the same data.
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Mapping
from typing import Any

_BARE = re.compile(r"^[A-Za-z0-9_-]+$")


def _key(k: str) -> str:
    return k if _BARE.match(k) else json.dumps(k)


def value(v: Any) -> str:
    """One TOML value."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if not math.isfinite(v):
            raise ValueError(f"TOML cannot hold {v}")
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v, ensure_ascii=False)  # a JSON string is a valid TOML basic string
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(value(x) for x in v) + "]"
    if isinstance(v, Mapping):
        return "{ " + ", ".join(f"{_key(str(k))} = {value(x)}" for k, x in v.items()) + " }"
    raise TypeError(f"TOML cannot hold {type(v).__name__}: {v!r}")


def dumps(data: Mapping[str, Any], *, header: str = "") -> str:
    """``data`` as a TOML document (``header``: comment lines at the top)."""
    lines: list[str] = [f"# {line}".rstrip() for line in header.splitlines()]
    _table(lines, data, [])
    return "\n".join(lines).strip("\n") + "\n"


def _table(lines: list[str], data: Mapping[str, Any], path: list[str]) -> None:
    scalars = {k: v for k, v in data.items() if not isinstance(v, Mapping)}
    tables = {k: v for k, v in data.items() if isinstance(v, Mapping)}
    if path and (scalars or not tables):
        lines.append("")
        lines.append("[" + ".".join(_key(p) for p in path) + "]")
    for k, v in scalars.items():
        lines.append(f"{_key(str(k))} = {value(v)}")
    for k, v in tables.items():
        _table(lines, v, [*path, str(k)])
