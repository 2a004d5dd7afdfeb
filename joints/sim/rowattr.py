"""Attributes that are columns of a kernel row: how a twin object shows its row's floats by name.

Rule: a twin whose working state lives in a kernel row (:mod:`joints.sim.kernel`) keeps no copy of it;
each named attribute reads and writes its column (``self._row[k]``, read through ``self._get(k)``, the
row's fastest float getter), so the compiled loops and the Python object never disagree.
"""

from __future__ import annotations

from typing import Any

__all__ = ["column", "flag"]


def column(k: int, doc: str = "") -> property:
    """A float attribute that is column ``k`` of the object's row."""

    def get(self: Any) -> float:
        return float(self._get(k))

    def put(self: Any, value: float) -> None:
        self._row[k] = float(value)

    return property(get, put, doc=doc)


def flag(k: int, doc: str = "") -> property:
    """A bool attribute held as 0.0 / 1.0 in column ``k`` of the object's row."""

    def get(self: Any) -> bool:
        return bool(self._get(k) != 0.0)

    def put(self: Any, value: bool) -> None:
        self._row[k] = 1.0 if value else 0.0

    return property(get, put, doc=doc)
