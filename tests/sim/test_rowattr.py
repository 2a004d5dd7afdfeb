"""Each kernel row is declared once: its index constants and the twins' row attributes come from the declaration.

A declared column without its twin attribute, a twin attribute that shadows or repeats a column by hand, or an
index constant that is not its column's index fails here.
"""

from __future__ import annotations

import ast
import inspect
import math
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np
import pytest

from joints.devices.erob.profiles import DEFAULT_MODEL as EROB_MODEL
from joints.devices.erob.profiles import profile as erob_profile
from joints.devices.zlac.profile import DEFAULT_MODEL as ZLAC_MODEL
from joints.devices.zlac.profile import profile as zlac_profile
from joints.sim import erob, erob_kernel, rowattr, zlac, zlac_kernel
from joints.sim.rowattr import Code, Columns, Flag, Int, Maybe, Real

#: (kernel module, declaration, the twin class that shows it)
ROWS: list[tuple[ModuleType, type[Columns], type[Any]]] = [
    (erob_kernel, erob_kernel.Columns, erob.ErobFirmware),
    (zlac_kernel, zlac_kernel.DriveColumns, zlac.ZlacFirmware),
    (zlac_kernel, zlac_kernel.ChannelColumns, zlac.ZlacChannel),
]
IDS = [decl.__name__ for _, decl, _ in ROWS]


@pytest.mark.parametrize(("module", "decl", "twin"), ROWS, ids=IDS)
def test_every_declared_column_is_an_index_constant_and_a_twin_attribute(
        module: ModuleType, decl: type[Columns], twin: type[Any]) -> None:
    assert decl.DECLARED, "no columns declared"
    assert [c.index for c in decl.DECLARED] == list(range(len(decl.DECLARED)))
    assert len({c.const for c in decl.DECLARED}) == len(decl.DECLARED)
    assert module.WIDTH >= len(decl.DECLARED)
    for c in decl.DECLARED:
        value = getattr(module, c.const)
        assert type(value) is int and value == c.index, (c.name, c.const, value)
        assert c.doc.strip(), f"{c.name}: say what the column means (and its unit)"
        generated = vars(decl)[c.name]
        assert type(generated) is property  # as cheap as a hand-written property
        assert generated.__doc__ == c.doc
        # the twin shows the declaration's attribute, nothing of its own shadows it
        assert inspect.getattr_static(twin, c.name) is generated, f"{twin.__name__}.{c.name} is not the declared one"


def _twins(numpy_rows: bool) -> list[tuple[type[Columns], Any, Any]]:
    """(declaration, twin object, its row) for a fresh eRob and ZLAC twin, on lists or on numpy rows."""
    e = erob.ErobFirmware(erob_profile(EROB_MODEL), 1)
    z = zlac.ZlacFirmware(zlac_profile(ZLAC_MODEL), 1)
    if numpy_rows:
        e.adopt(np.zeros((1, erob_kernel.WIDTH)), 0)
        z.adopt(np.zeros((3, zlac_kernel.WIDTH)), 0)
    return [(erob_kernel.Columns, e, e._row), (zlac_kernel.DriveColumns, z, z._drow),
            (zlac_kernel.ChannelColumns, z.left, z.left._row), (zlac_kernel.ChannelColumns, z.right, z.right._row)]


@pytest.mark.parametrize("numpy_rows", [False, True], ids=["python", "compiled"])
def test_each_twin_attribute_reads_and_writes_its_own_column(numpy_rows: bool) -> None:
    for decl, obj, row in _twins(numpy_rows):
        for c in decl.DECLARED:
            if isinstance(c, Code):
                value: Any = c.table[-1]
                stored = float(len(c.table) - 1)
            elif isinstance(c, Flag):
                value, stored = True, 1.0
            elif isinstance(c, Int):
                value, stored = 1000 + c.index, float(1000 + c.index)
            else:
                assert isinstance(c, (Real, Maybe))
                value = stored = 0.25 + c.index
            before = [repr(float(x)) for x in row]
            setattr(obj, c.name, value)
            after = [repr(float(x)) for x in row]
            assert after[c.index] == repr(stored), (decl.__name__, c.name)
            assert [x for k, x in enumerate(after) if k != c.index] == \
                   [x for k, x in enumerate(before) if k != c.index], f"{c.name} wrote another column"
            got = getattr(obj, c.name)
            assert got == value and type(got) is type(value), (c.name, got, value)
            row[c.index] = before[c.index]  # as it was
    for _, obj, row in _twins(numpy_rows)[:2]:
        k = erob_kernel.BRAKE_HOLD if isinstance(obj, erob.ErobFirmware) else zlac_kernel.D_RAMP_REF
        name = "brake_hold" if isinstance(obj, erob.ErobFirmware) else "ramp_reference"
        setattr(obj, name, None)
        assert math.isnan(row[k]) and getattr(obj, name) is None


def _reads_one_column(fn: ast.FunctionDef) -> bool:
    """A getter that is one ``return`` of one row read (``..._get(k)`` / ``..._dget(k)``), at most converted."""
    if len(fn.body) != 1 or not isinstance(fn.body[0], ast.Return) or fn.body[0].value is None:
        return False
    calls = [n for n in ast.walk(fn.body[0].value) if isinstance(n, ast.Call)]
    reads = [n for n in calls if isinstance(n.func, ast.Attribute) and n.func.attr in ("_get", "_dget")]
    others = [n for n in calls if n not in reads and not (isinstance(n.func, ast.Name)
                                                          and n.func.id in ("float", "int", "bool"))]
    return len(reads) == 1 and not others


@pytest.mark.parametrize("module", [erob, zlac], ids=["erob", "zlac"])
def test_no_twin_lists_its_row_attributes_by_hand(module: ModuleType) -> None:
    """A property that only reads one column, or a ``property(...)`` made in a class body, is a column
    declared a second time: declare it in the kernel's row instead."""
    tree = ast.parse(Path(module.__file__ or "").read_text())
    found = []
    for cls in (n for n in ast.walk(tree) if isinstance(n, ast.ClassDef)):
        for item in cls.body:
            if isinstance(item, ast.FunctionDef) and any(
                    isinstance(d, ast.Name) and d.id == "property" for d in item.decorator_list) \
                    and _reads_one_column(item):
                found.append(f"{cls.name}.{item.name}")
            if isinstance(item, (ast.Assign, ast.AnnAssign)) and isinstance(item.value, ast.Call) and \
                    isinstance(item.value.func, (ast.Name, ast.Attribute)) and \
                    (getattr(item.value.func, "id", None) or getattr(item.value.func, "attr", None)) in (
                        "property", "column", "flag", "Real", "Flag", "Int", "Code", "Maybe"):
                found.append(f"{cls.name}: {ast.unparse(item)[:60]}")
    assert not found, f"row attributes written by hand: {found}"


def test_a_row_is_declared_once() -> None:
    """A declaration cannot be extended by a subclass (the indices would fork), and a wrong index constant
    fails at import."""
    with pytest.raises(TypeError, match="declared once"):
        type("More", (erob_kernel.Columns,), {"extra": Real("an extra column [1]")})
    namespace = dict(vars(erob_kernel))
    namespace["POS"], namespace["VEL"] = namespace["VEL"], namespace["POS"]
    with pytest.raises(ImportError, match="POS"):
        rowattr.bind(namespace, erob_kernel.Columns)
