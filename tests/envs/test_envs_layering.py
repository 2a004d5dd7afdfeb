"""envs/ sits on top of DESIGN.md section 3: it imports the public joints API only (the package and
its exceptions) and uses the rig's public sim API (``rig.sim``), nothing private."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
ALLOWED = {"joints", "joints.errors"}


def test_envs_import_only_the_public_joints_api() -> None:
    found: dict[str, set[str]] = {}
    for path in sorted((ROOT / "envs").rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            names: list[str] = []
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
                names = [node.module]
            for n in names:
                if n == "joints" or n.startswith("joints."):
                    found.setdefault(n, set()).add(path.name)
    assert found, "envs should use joints"
    assert set(found) <= ALLOWED, {k: v for k, v in found.items() if k not in ALLOWED}


def test_envs_touch_nothing_private_of_joints() -> None:
    """No ``._name`` attribute of a joints object (the rig, a joint, the sim world, a driver)."""
    offenders = []
    for path in sorted((ROOT / "envs").rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Attribute) and node.attr.startswith("_") and not node.attr.startswith("__"):
                base = ast.unparse(node.value)
                if base != "self" and not base.startswith("self._") and not base.startswith("type("):
                    offenders.append(f"{path.name}:{node.lineno}: {base}.{node.attr}")
    assert not offenders, offenders


def test_joints_never_imports_envs() -> None:
    for path in (ROOT / "joints").rglob("*.py"):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                assert not any(a.name.split(".")[0] == "envs" for a in node.names), path
            elif isinstance(node, ast.ImportFrom) and node.module:
                assert node.module.split(".")[0] != "envs", path
