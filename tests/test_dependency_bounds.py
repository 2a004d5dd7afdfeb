"""The lowest-versions constraints of CI (.ci/lowest.txt) are the lower bounds pyproject.toml states.

Every direct dependency in pyproject.toml (core and every extra) has a ``>=`` lower bound, one bound
per package wherever it is named, and .ci/lowest.txt pins exactly those packages at exactly those
versions - so the versions CI's lowest run installs cannot drift from the ones the project claims.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

ROOT = Path(__file__).resolve().parents[1]
REQUIREMENT = re.compile(r"^\s*([A-Za-z0-9][A-Za-z0-9._-]*)\s*(\[[^\]]*\])?\s*>=\s*([0-9][0-9.]*)\s*(;.*)?$")


def _name(name: str) -> str:
    return re.sub(r"[-_.]+", "-", name).lower()  # PEP 503


def _version(text: str) -> tuple[int, ...]:
    parts = [int(p) for p in text.split(".")]
    while len(parts) > 1 and parts[-1] == 0:
        parts.pop()
    return tuple(parts)


def lower_bounds() -> dict[str, str]:
    project = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]
    requirements = list(project["dependencies"])
    for extra in project["optional-dependencies"].values():
        requirements += [r for r in extra if _name(re.split(r"[\[<>=;\s]", r)[0]) != "joints"]
    bounds: dict[str, str] = {}
    for req in requirements:
        m = REQUIREMENT.match(req)
        assert m, f"pyproject.toml: {req!r} states no lower bound (name>=X.Y.Z) or more than one"
        name, version = _name(m.group(1)), m.group(3)
        assert _version(bounds.get(name, version)) == _version(version), f"{name}: two lower bounds"
        bounds[name] = version
    return bounds


def pins() -> tuple[dict[str, str], set[str]]:
    """(name -> pinned version, names constrained otherwise: packages that are not direct dependencies)."""
    out: dict[str, str] = {}
    others: set[str] = set()
    for line in (ROOT / ".ci" / "lowest.txt").read_text(encoding="utf-8").splitlines():
        line = line.split("#", 1)[0].strip()
        if not line:
            continue
        name, sep, version = line.partition("==")
        if not sep:
            others.add(_name(re.split(r"[<>=!~;\s]", line)[0]))
            continue
        assert version.strip(), f".ci/lowest.txt: {line!r} is not name==version"
        assert _name(name) not in out, f".ci/lowest.txt: {name} twice"
        out[_name(name)] = version.strip()
    return out, others


def test_lowest_constraints_are_the_pyproject_lower_bounds() -> None:
    bounds, (pinned, others) = lower_bounds(), pins()
    assert set(pinned) == set(bounds), (sorted(set(bounds) - set(pinned)), sorted(set(pinned) - set(bounds)))
    assert not others & set(bounds), f"a direct dependency is constrained but not pinned: {others & set(bounds)}"
    wrong = {n: (bounds[n], pinned[n]) for n in bounds if _version(bounds[n]) != _version(pinned[n])}
    assert not wrong, f"pyproject bound vs .ci/lowest.txt pin: {wrong}"
    assert {"numpy", "mujoco", "numba", "gymnasium", "python-can", "pytest"} <= set(bounds)
