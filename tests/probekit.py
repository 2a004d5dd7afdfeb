"""What the A/B probes (``tests/*/*_ab_probe.py``, measuring tools, not tests) share: loading another
checkout's module under another name, so both versions run in one process."""

from __future__ import annotations

import importlib.util
import os
import sys
from typing import Any


def load_as(root: str, rel: str, name: str) -> Any:
    """The module at ``root``/``rel`` (another checkout's file), imported as ``name``."""
    spec = importlib.util.spec_from_file_location(name, os.path.join(root, rel))
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module
