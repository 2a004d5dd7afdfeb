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


#: envs/batch.py is JointsEnv's own step written across a batch's rigs: it reads and sets each rig env's own
#: private state (the rigs are JointsEnv objects it names ``e`` / ``first``; ``JointsEnv`` / ``self.kind`` their class)
ENV_BASES = {"batch.py": {"e", "first", "JointsEnv", "self.kind"}}


def _env_private_names() -> set[str]:
    """Private attributes and methods the envs' own classes define (``self._x = ...``, ``def _x``)."""
    names = set()
    for path in (ROOT / "envs").rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Attribute) and isinstance(node.ctx, ast.Store) and ast.unparse(node.value) == "self":
                names.add(node.attr)
            elif isinstance(node, ast.FunctionDef):
                names.add(node.name)
    return {n for n in names if n.startswith("_") and not n.startswith("__")}


def test_envs_touch_nothing_private_of_joints() -> None:
    """No ``._name`` attribute of a joints object (the rig, a joint, the sim world, a driver); the batch module may
    touch its rig envs' own private names (:data:`ENV_BASES`), no other."""
    own = _env_private_names()
    offenders = []
    for path in sorted((ROOT / "envs").rglob("*.py")):
        env_bases = ENV_BASES.get(path.name, set())
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Attribute) and node.attr.startswith("_") and not node.attr.startswith("__"):
                base = ast.unparse(node.value)
                if base in env_bases and node.attr in own:
                    continue
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
