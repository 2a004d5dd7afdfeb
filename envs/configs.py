"""The shipped default configs (package data of ``joints.configs``).

``default_config("erob_reach")`` returns the parsed TOML as a dict, so a script can change a key
(e.g. the bus port for hardware) and hand the dict to an env::

    cfg = envs.default_config("erob_reach")
    cfg["buses"]["rs485"]["port"] = "/dev/ttyUSB0"
    env = gymnasium.make("joints/ErobReach-v0", config=cfg, backend="hardware")
"""

from __future__ import annotations

import contextlib
import sys
from collections.abc import Iterator
from importlib import resources
from pathlib import Path
from typing import Any

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

#: names of the shipped configs (files ``joints/configs/<name>.toml``)
SHIPPED = ("erob_reach", "erob_arm_reach", "zlac_diffdrive", "mks_axis")


def _ref(name: str) -> Any:
    stem = name.removesuffix(".toml")
    if stem not in SHIPPED:
        raise ValueError(f"no shipped config {name!r}; shipped: {list(SHIPPED)}")
    return resources.files("joints.configs") / f"{stem}.toml"


@contextlib.contextmanager
def config_path(name: str) -> Iterator[Path]:
    """A filesystem path of the shipped config ``name`` (valid inside the ``with`` block)."""
    with resources.as_file(_ref(name)) as p:
        yield Path(p)


def default_config(name: str) -> dict[str, Any]:
    """The shipped config ``name`` (one of SHIPPED) as a fresh, editable dict."""
    data: dict[str, Any] = tomllib.loads(_ref(name).read_text(encoding="utf-8"))
    return data
