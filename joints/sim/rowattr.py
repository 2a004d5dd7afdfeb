"""Kernel rows declared once: each column's name, meaning and unit, and how a twin shows it.

Rule: a kernel row (:mod:`joints.sim.kernel`) is declared by one class of :class:`Columns`: its class
attributes that are :class:`Column` objects, in order, are the row's columns (index 0, 1, ...), each with
its meaning and unit (``doc``) and the name of its index constant in the kernel module (``const``). From
that declaration come the twin's attributes - the twin class inherits the declaration, whose columns
are then plain ``property`` objects reading ``self._get(k)`` (the row's fastest float getter) and writing
``self._row[k]`` (the twin keeps no copy, so the compiled loops and the Python object never disagree) -
and the kernel module's index constants, which stay plain ``int`` globals written out in that module
(numba reads them as compile-time constants, mypy and ruff see them): :func:`bind` checks, at import,
that each is the index of its column.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any, ClassVar, Generic, TypeVar, overload

__all__ = ["Code", "Column", "Columns", "Flag", "Int", "Maybe", "Real", "bind", "indices", "names", "params"]

T = TypeVar("T")


class Column(Generic[T]):
    """One column of a kernel row as declared: ``doc`` its meaning and unit; ``const`` the name of its index
    constant (default: the prefix of its row and its name in capitals); ``param`` it holds the firmware
    parameter of its name (kept equal to it by the twin). The twin's attribute is :meth:`attribute`."""

    def __init__(self, doc: str, *, const: str | None = None, param: bool = False) -> None:
        self.doc = doc
        self.const = const or ""
        self.param = param
        self.name = ""  #: the twin's attribute (set when the declaring class is made)
        self.index = -1  #: the column (its place in the declaration)

    def attribute(self) -> property:  # pragma: no cover - every kind defines it
        """The twin's attribute for this column (a plain ``property``: as cheap as a hand-written one)."""
        raise NotImplementedError

    if TYPE_CHECKING:  # the declaring class holds properties instead: these give mypy their types
        @overload
        def __get__(self, obj: None, owner: type[Any]) -> property: ...

        @overload
        def __get__(self, obj: object, owner: type[Any] | None = None) -> T: ...

        def __get__(self, obj: object, owner: type[Any] | None = None) -> T | property: ...

        def __set__(self, obj: object, value: T) -> None: ...


class Real(Column[float]):
    """A float."""

    def attribute(self) -> property:
        k = self.index

        def get(self: Any) -> float:
            return float(self._get(k))

        def put(self: Any, value: float) -> None:
            self._row[k] = float(value)

        return property(get, put, doc=self.doc)


class Flag(Column[bool]):
    """A bool held as 0.0 / 1.0."""

    def attribute(self) -> property:
        k = self.index

        def get(self: Any) -> bool:
            return bool(self._get(k) != 0.0)

        def put(self: Any, value: bool) -> None:
            self._row[k] = 1.0 if value else 0.0

        return property(get, put, doc=self.doc)


class Int(Column[int]):
    """An integer held as an exact float (a code, a register value, a count)."""

    def attribute(self) -> property:
        k = self.index

        def get(self: Any) -> int:
            return int(self._get(k))

        def put(self: Any, value: int) -> None:
            self._row[k] = float(value)

        return property(get, put, doc=self.doc)


class Code(Column[T]):
    """One of ``table``, held as its index (a state code)."""

    def __init__(self, table: Sequence[T], doc: str, *, const: str | None = None) -> None:
        super().__init__(doc, const=const)
        self.table = tuple(table)

    def attribute(self) -> property:
        k = self.index
        table = self.table

        def get(self: Any) -> T:
            return table[int(self._get(k))]

        def put(self: Any, value: T) -> None:
            self._row[k] = float(table.index(value))

        return property(get, put, doc=self.doc)


class Maybe(Column[float | None]):
    """A float or None, held as NaN."""

    def attribute(self) -> property:
        k = self.index

        def get(self: Any) -> float | None:
            x = float(self._get(k))
            return None if math.isnan(x) else x

        def put(self: Any, value: float | None) -> None:
            self._row[k] = math.nan if value is None else float(value)

        return property(get, put, doc=self.doc)


class Columns:
    """A kernel row's declaration (subclass it and declare the columns in order); a twin inherits it.

    ``PREFIX`` starts the default names of the index constants (a row kind sharing its module with another).
    """

    __slots__ = ()
    PREFIX: ClassVar[str] = ""
    DECLARED: ClassVar[tuple[Column[Any], ...]] = ()  #: the columns, in order

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        own = [(name, c) for name, c in vars(cls).items() if isinstance(c, Column)]
        if not own:  # a twin inheriting a declaration
            return
        if cls.DECLARED:
            raise TypeError(f"{cls.__name__}: a kernel row is declared once (its columns extend {cls.__mro__[1]})")
        for k, (name, c) in enumerate(own):
            c.name, c.index = name, k
            c.const = c.const or cls.PREFIX + name.upper()
            setattr(cls, name, c.attribute())
        cls.DECLARED = tuple(c for _, c in own)


def indices(columns: type[Columns]) -> range:
    """The columns' indices, in order (what the kernel module's index constants are unpacked from)."""
    return range(len(columns.DECLARED))


def names(columns: type[Columns]) -> tuple[str, ...]:
    """The columns' names, in order."""
    return tuple(c.name for c in columns.DECLARED)


def params(columns: type[Columns]) -> dict[str, int]:
    """Firmware parameter name -> its column, for the columns that hold one."""
    return {c.name: c.index for c in columns.DECLARED if c.param}


def bind(namespace: Mapping[str, Any], columns: type[Columns]) -> int:
    """Check that every declared column's index constant in ``namespace`` (its kernel module's globals) is a
    plain ``int`` equal to its index, and no other; return the row's width."""
    for c in columns.DECLARED:
        value = namespace.get(c.const)
        if type(value) is not int or value != c.index:
            raise ImportError(f"{columns.__name__}.{c.name}: the index constant {c.const} is {value!r}, "
                              f"not {c.index} (declare the constants in the columns' order)")
    return len(columns.DECLARED)
