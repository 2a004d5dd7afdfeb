"""The import direction of DESIGN.md section 3, checked by parsing every module under joints/.

Every import counts - at module level or inside a function (lazy imports still couple the layers) -
except those under ``if TYPE_CHECKING:``, which exist for annotations only.
"""

from __future__ import annotations

import ast
import json
import os
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "joints"

#: the package itself (``import joints`` / ``from joints import open``) is the public API: everything
API = "api"

#: layer -> the layers it may import besides its own
ALLOWED: dict[str, frozenset[str]] = {
    "errors": frozenset(),
    "clock": frozenset(),
    "exits": frozenset(),  # leaving safely: signals and atexit close open rigs
    # the config's types (BusConfig, JointConfig, Limits, Motion ...): a leaf the parser, registry and joint share
    "configtypes": frozenset({"errors"}),
    "codecs": frozenset({"errors"}),
    "devices": frozenset({"errors"}),
    "transports": frozenset({"errors"}),
    "link": frozenset({"codecs", "transports", "clock", "errors"}),
    "drivers": frozenset({"link", "devices", "codecs", "clock", "errors"}),
    "joint": frozenset({"drivers", "devices", "clock", "errors", "configtypes"}),
    # the one list of device families and protocols: it names every driver, link and twin
    "registry": frozenset({"errors", "clock", "codecs", "devices", "transports", "link", "drivers", "sim",
                           "configtypes"}),
    "config": frozenset({"configtypes", "errors", "registry"}),
    # the sim's compiled command/state path: joints and drivers of in-process twins, without the rig
    "compiled_path": frozenset({"errors", "clock", "codecs", "devices", "transports", "link", "drivers", "joint"}),
    # emulated drives: device semantics + transports to be served on; never the host side
    "sim": frozenset({"devices", "codecs", "transports", "clock", "errors"}),
    "rig": frozenset({"errors", "clock", "codecs", "devices", "transports", "link", "drivers", "joint",
                      "registry", "config", "configtypes", "sim", "exits"}),
    # sim-to-real (identify, shadow, record/replay): the public rig/joint API plus the twins it builds
    "s2r": frozenset({"errors", "clock", "codecs", "devices", "transports", "link", "drivers", "joint",
                      "registry", "config", "configtypes", "sim", "rig", "exits"}),
    "cli": frozenset({"errors", "clock", "codecs", "devices", "transports", "link", "drivers", "joint",
                      "registry", "config", "configtypes", "sim", "rig", "exits", "s2r", "bench", API}),
    # `joints bench`: measures every layer against its reference (issue 23)
    "bench": frozenset({"errors", "clock", "codecs", "devices", "transports", "link", "drivers", "joint",
                        "registry", "config", "configtypes", "sim", "rig", "exits", API}),
}
#: the package entry points import whatever they re-export
EXEMPT = {"joints", "joints.__main__"}


def layer_of(module: str) -> str:
    """``joints.link.modbus`` -> ``link``; ``joints`` -> the public API."""
    parts = module.split(".")
    assert parts[0] == "joints", module
    if len(parts) == 1:
        return API
    return parts[1]


def module_name(path: Path) -> str:
    rel = path.relative_to(ROOT).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def modules() -> list[Path]:
    return sorted(p for p in PACKAGE.rglob("*.py") if "__pycache__" not in p.parts)


def is_submodule(dotted: str) -> bool:
    """Whether ``joints.x.y`` names a module or package on disk (else it is an attribute)."""
    base = ROOT.joinpath(*dotted.split("."))
    return base.with_suffix(".py").is_file() or (base / "__init__.py").is_file()


def _is_type_checking(test: ast.expr) -> bool:
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING"
    )


@dataclass(frozen=True)
class Import:
    target: str  #: the joints module imported
    line: int


class ImportCollector(ast.NodeVisitor):
    """All imports of one module, resolved to absolute ``joints...`` module names."""

    def __init__(self, module: str, is_package: bool) -> None:
        self.module = module
        self.package = module if is_package else module.rpartition(".")[0]
        self.found: list[Import] = []

    def visit_If(self, node: ast.If) -> None:
        if _is_type_checking(node.test):
            for child in node.orelse:  # the else branch runs
                self.visit(child)
            return
        self.generic_visit(node)

    def visit_Import(self, node: ast.Import) -> None:
        for alias in node.names:
            if alias.name == "joints" or alias.name.startswith("joints."):
                self.found.append(Import(alias.name, node.lineno))

    def visit_ImportFrom(self, node: ast.ImportFrom) -> None:
        if node.level:
            base = self.package.split(".")
            if node.level > 1:
                base = base[: -(node.level - 1)]
            source = ".".join(base + ([node.module] if node.module else []))
        else:
            source = node.module or ""
        if not (source == "joints" or source.startswith("joints.")):
            return
        for alias in node.names:
            sub = f"{source}.{alias.name}"
            # ``from joints import rig`` imports the module joints.rig; ``from joints import open`` the API
            self.found.append(Import(sub if is_submodule(sub) else source, node.lineno))


def imports_of(path: Path) -> list[Import]:
    name = module_name(path)
    collector = ImportCollector(name, path.name == "__init__.py")
    collector.visit(ast.parse(path.read_text(encoding="utf-8"), filename=str(path)))
    return collector.found


def test_every_module_has_a_layer() -> None:
    unknown = sorted(
        module_name(p) for p in modules()
        if module_name(p) not in EXEMPT and layer_of(module_name(p)) not in ALLOWED
    )
    assert not unknown, (
        f"modules outside every layer of DESIGN.md section 3: {unknown}; "
        "place them in a layer and add it to ALLOWED in this test"
    )


def test_imports_flow_one_way() -> None:
    violations: list[str] = []
    for path in modules():
        name = module_name(path)
        if name in EXEMPT:
            continue
        layer = layer_of(name)
        allowed = ALLOWED.get(layer, frozenset()) | {layer}
        for imp in imports_of(path):
            target = layer_of(imp.target)
            if target not in allowed:
                violations.append(
                    f"{path.relative_to(ROOT)}:{imp.line}: {layer} imports {imp.target} ({target}); "
                    f"{layer} may import only {sorted(allowed)}"
                )
    assert not violations, "import direction violated:\n" + "\n".join(violations)


# --- the checker itself -----------------------------------------------------------------------


def _collect(source: str, module: str = "joints.sim.fake", is_package: bool = False) -> list[str]:
    collector = ImportCollector(module, is_package)
    collector.visit(ast.parse(source))
    return [i.target for i in collector.found]


def test_checker_sees_lazy_relative_and_from_imports() -> None:
    src = (
        "import os\n"
        "from typing import TYPE_CHECKING\n"
        "import joints.link.modbus\n"
        "from joints import rig\n"
        "from joints import open\n"
        "from . import firmware\n"
        "from ..drivers import base\n"
        "def f():\n"
        "    from joints.joint import Joint\n"
        "    return Joint\n"
        "if TYPE_CHECKING:\n"
        "    from joints.config import RigConfig\n"
        "else:\n"
        "    from joints.clock import ManualClock\n"
    )
    assert _collect(src) == [
        "joints.link.modbus",
        "joints.rig",
        "joints",
        "joints.sim.firmware",
        "joints.drivers.base",
        "joints.joint",
        "joints.clock",
    ]


def test_checker_flags_typing_dot_type_checking_as_exempt() -> None:
    src = "import typing\nif typing.TYPE_CHECKING:\n    from joints.rig import Rig\n"
    assert _collect(src) == []


def test_checker_resolves_relative_imports_in_a_package_init() -> None:
    assert _collect("from .modbus import ModbusLink\n", "joints.link", is_package=True) == ["joints.link.modbus"]


@pytest.mark.parametrize("layer,forbidden", [("sim", "drivers"), ("sim", "joint"), ("sim", "rig"), ("sim", "link"),
                                             ("codecs", "transports"), ("devices", "codecs"),
                                             ("joint", "link"), ("config", "drivers"), ("rig", "cli"),
                                             ("drivers", "joint"), ("link", "drivers"), ("clock", "errors"),
                                             ("drivers", "registry"), ("sim", "registry"), ("drivers", "config"),
                                             ("configtypes", "registry"), ("configtypes", "config"),
                                             ("registry", "config"), ("joint", "config")])
def test_rules_forbid(layer: str, forbidden: str) -> None:
    assert forbidden not in ALLOWED[layer]


# --- optional heavy dependencies --------------------------------------------------------------

HEAVY = ("mujoco", "serial", "can", "gymnasium")


def test_import_joints_pulls_in_no_heavy_dependency() -> None:
    code = (
        "import json, sys\n"
        "import joints\n"
        f"heavy = {HEAVY!r}\n"
        "print(json.dumps(sorted(m for m in sys.modules if m.split('.')[0] in heavy)))\n"
    )
    env = dict(os.environ)
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    env.pop("JOINTS_BACKEND", None)
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, env=env,
                          timeout=60, check=False)
    assert proc.returncode == 0, proc.stderr
    assert json.loads(proc.stdout.strip().splitlines()[-1]) == []


# --- one list of devices: names are compared only in the registry and the device's own modules ---

#: where a device family's name may appear in a comparison (its own definitions and the registry)
DEVICE_HOMES = ("joints/registry.py", "joints/devices/")


def _device_names() -> set[str]:
    from joints import registry

    return set(registry.devices()) | set(registry.PLANNED_DEVICES)


def name_tests(tree: ast.AST, names: set[str]) -> list[tuple[int, str]]:
    """Where ``tree`` compares with one of ``names`` (``==``, ``!=``, ``in``, a ``match`` case), picks by one
    (``x["name"]``, ``x.get("name")``) or chooses one (``"name" if c else ...``): special-casing a device or
    protocol by its name."""
    found: list[tuple[int, str]] = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Compare):
            found += [(node.lineno, c.value) for c in ast.walk(node)
                      if isinstance(c, ast.Constant) and isinstance(c.value, str) and c.value in names]
        elif isinstance(node, ast.MatchValue):
            if isinstance(node.value, ast.Constant) and node.value.value in names:
                found.append((node.lineno, node.value.value))
        elif isinstance(node, ast.Subscript):
            if isinstance(node.slice, ast.Constant) and node.slice.value in names:
                found.append((node.lineno, node.slice.value))
        elif isinstance(node, ast.IfExp):
            found += [(node.lineno, c.value) for c in (node.body, node.orelse)
                      if isinstance(c, ast.Constant) and isinstance(c.value, str) and c.value in names]
        elif (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr == "get"
              and node.args and isinstance(node.args[0], ast.Constant) and node.args[0].value in names):
            found.append((node.lineno, node.args[0].value))
    return found


def _name_offenders(names: set[str], homes: tuple[str, ...]) -> list[str]:
    offenders: list[str] = []
    for path in [*modules(), *sorted((ROOT / "envs").rglob("*.py"))]:
        rel = path.relative_to(ROOT).as_posix()
        if rel.startswith(homes):
            continue
        for line, name in name_tests(ast.parse(path.read_text(encoding="utf-8")), names):
            offenders.append(f"{rel}:{line}: compares with {name!r}")
    return offenders


def test_no_comparison_against_a_device_name_outside_the_registry() -> None:
    offenders = _name_offenders(_device_names(), DEVICE_HOMES)
    assert not offenders, "device names compared outside the registry:\n" + "\n".join(offenders)


def _protocol_names() -> set[str]:
    from joints import registry

    return set(registry.protocols()) | set(registry.PLANNED_PROTOCOLS)


def test_no_comparison_against_a_protocol_name_outside_the_registry() -> None:
    """A protocol's differences are attributes of its registry entry (medium, silence, sync, values ...)."""
    offenders = _name_offenders(_protocol_names(), ("joints/registry.py",))
    assert not offenders, ("protocol names compared outside the registry (ask registry.protocol(name) for the "
                           "attribute instead):\n" + "\n".join(offenders))


@pytest.mark.parametrize("source", [
    'if bus.protocol == "canopen":\n    pass\n',
    'x = protocol in ("modbus-rtu", "mks-serial")\n',
    'x = "erob-can" != p\n',
    'match p:\n    case "canopen":\n        pass\n',
    'x = fam.tables.get("modbus-rtu")\n',
    'x = fam.drivers["mks-serial"]\n',
    'x = a or ("modbus-rtu" if port else "erob-can")\n',
])
def test_the_name_check_sees_every_way_to_special_case_a_protocol(source: str) -> None:
    assert name_tests(ast.parse(source), _protocol_names())


def test_the_name_check_lets_definitions_and_other_strings_pass() -> None:
    source = ('protocol = "modbus-rtu"\n'  # a link's or driver's own protocol
              'PARAMS = ParamMap("canopen", params, keys)\n'
              'if bus.protocol == other:\n    pass\n'
              'x = cfg["buses"].get("rs485")\n')
    assert name_tests(ast.parse(source), _protocol_names()) == []


def test_no_capability_probing_by_attribute_name() -> None:
    """Optional driver abilities are typed protocols (joints.drivers.capabilities), not getattr/hasattr probes."""
    probes = {"getattr", "hasattr"}
    offenders: list[str] = []
    cli = sorted(p.relative_to(ROOT).as_posix() for p in (ROOT / "joints" / "cli").glob("*.py"))
    for rel in ("joints/rig.py", "joints/joint.py", "joints/registry.py", "joints/config.py", *cli):
        path = ROOT / rel
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in probes:
                offenders.append(f"{rel}:{node.lineno}")
    for path in sorted((ROOT / "envs").rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if (isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in probes
                    and node.args and isinstance(node.args[0], ast.Attribute) and "driver" in ast.unparse(node.args[0])):
                offenders.append(f"{path.relative_to(ROOT)}:{node.lineno}")
    assert not offenders, f"attribute probing where a capability protocol belongs: {offenders}"


def self_probes(tree: ast.AST) -> list[int]:
    """Lines where an object asks whether it has one of its own attributes (``hasattr(self, "_x")``,
    ``getattr(self, "_x", default)``) instead of initialising it; ``getattr(self, f.name)`` of a field
    loop names no attribute and passes."""
    return [node.lineno for node in ast.walk(tree)
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in ("getattr", "hasattr")
            and len(node.args) >= 2 and isinstance(node.args[0], ast.Name) and node.args[0].id == "self"
            and isinstance(node.args[1], ast.Constant)]


def test_envs_initialise_their_attributes_instead_of_probing_them() -> None:
    offenders = [f"{path.relative_to(ROOT)}:{line}" for path in sorted((ROOT / "envs").rglob("*.py"))
                 for line in self_probes(ast.parse(path.read_text(encoding="utf-8")))]
    assert not offenders, f"an env probes its own attributes (initialise them instead): {offenders}"


def test_the_self_probe_check_sees_both_forms() -> None:
    tree = ast.parse('if getattr(self, "_closed", True):\n    pass\nif not hasattr(self, "_obs"):\n    pass\n'
                     "x = [getattr(self, f.name) for f in fields(self)]\ny = getattr(env, 'x')\n")
    assert self_probes(tree) == [1, 3]
