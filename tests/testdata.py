"""Test data vendored from ../shared into tests/data (refresh with ``python tests/data/refresh.py``).

Rule: tests read vectors and manual text from here, never from outside the repository, so a fresh
clone runs every test. ``tests/test_testdata.py`` checks the files against their manifest and,
where ../shared exists beside the checkout, against the originals.
"""

from __future__ import annotations

import json
from functools import cache
from pathlib import Path
from typing import Any

DATA = Path(__file__).resolve().parent / "data"
VECTORS = DATA / "vectors.json"
MANUALS = DATA / "manuals"


@cache
def records() -> tuple[dict[str, Any], ...]:
    """Every record of vectors.json (vectors, templates, sequences)."""
    return tuple(json.loads(VECTORS.read_text(encoding="utf-8")))


def vectors(protocol: str | None = None, device: str | None = None) -> list[dict[str, Any]]:
    """The ``vector`` records, optionally of one protocol and/or device."""
    return [r for r in records() if r.get("record_type") == "vector"
            and (protocol is None or r.get("protocol") == protocol)
            and (device is None or r.get("device") == device)]


def sequences(manual_contains: str) -> list[dict[str, Any]]:
    """The ``sequence`` records of the manuals whose file name contains ``manual_contains``."""
    return [r for r in records() if r.get("record_type") == "sequence" and manual_contains in str(r.get("manual", ""))]


def by_id() -> dict[str, dict[str, Any]]:
    return {r["id"]: r for r in records() if "id" in r}


def manual(name: str) -> str:
    """The text of a vendored manual (file name in tests/data/manuals)."""
    return (MANUALS / name).read_text(encoding="utf-8")
