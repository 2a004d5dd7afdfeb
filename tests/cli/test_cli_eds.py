"""`joints sim eds CONFIG NODE -o FILE`: the EDS of the emulated drive at a node, which the canopen package imports."""

from __future__ import annotations

from pathlib import Path

import pytest

from joints.cli import main

CONFIG = """
backend = "sim"
[sim]
model = "erob_arm3.xml"
[buses.can]
protocol = "canopen"
[buses.rs485]
protocol = "modbus-rtu"
[joints.joint1]
device = "erob"
bus = "can"
address = 3
[joints.joint2]
device = "erob"
bus = "can"
address = 17
[joints.joint3]
device = "erob"
bus = "rs485"
address = 5
"""


@pytest.fixture
def config(tmp_path: Path) -> Path:
    cfg = tmp_path / "arm.toml"
    cfg.write_text(CONFIG)
    return cfg


def test_eds_of_a_node_imports_with_the_canopen_package(config: Path, tmp_path: Path,
                                                        capsys: pytest.CaptureFixture[str]) -> None:
    canopen = pytest.importorskip("canopen")
    out = tmp_path / "joint2.eds"
    assert main(["sim", "eds", str(config), "17", "-o", str(out)]) == 0
    assert "joint2" in capsys.readouterr().err
    od = canopen.import_od(str(out), 17)
    assert od[0x6041].name == "Statusword" and od[0x6502].default == 0x3CD
    assert od[0x1400][1].default == 0x200 + 17 and od[0x1800][1].default == 0x180 + 17  # $NODEID-relative
    assert od[0x607A].pdo_mappable and od[0x6060].data_type == 0x0002
    assert od.device_information.vendor_name == "ZeroErr"


def test_eds_to_stdout(config: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["sim", "eds", str(config), "3"]) == 0
    text = capsys.readouterr().out
    assert "[6041]" in text and "$NODEID+0x180" in text


@pytest.mark.parametrize("node", ["4", "5"])  # nobody there; a Modbus joint has no EDS
def test_a_node_without_an_eds_is_a_config_error_naming_the_nodes(config: Path, node: str,
                                                                  capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["sim", "eds", str(config), node]) == 2
    err = capsys.readouterr().err
    assert f"no joint at node {node}" in err and "3, 17" in err
