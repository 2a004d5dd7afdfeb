"""Where `joints sim serve` puts a CAN bus: never on a real interface, never off this host."""

from __future__ import annotations

import ipaddress
from pathlib import Path

import pytest

from joints.errors import ConfigError
from joints.sim import can_serve
from joints.sim.can_serve import ServedCan, plan


def test_default_is_an_interface_local_udp_multicast_group_with_a_free_port() -> None:
    spec = plan("can", None, None, None, index=1)
    assert spec.interface == "udp_multicast"
    assert ipaddress.ip_address(spec.channel) in ipaddress.ip_network("ff01::/16")
    assert spec.udp_port is not None and 1024 <= spec.udp_port <= 65535
    assert spec.kwargs() == {"port": spec.udp_port, "hop_limit": 0}
    assert spec.line("can") == {"bus": "can", "interface": "udp_multicast", "channel": spec.channel,
                                "udp_port": spec.udp_port}


def test_two_buses_of_one_world_get_different_groups_and_ports() -> None:
    a, b = plan("a", None, None, None, index=0), plan("b", None, None, None, index=1)
    assert a.channel != b.channel


def test_in_process_interfaces_are_served_on_udp_multicast() -> None:
    for interface in ("virtual", "joints-sim"):
        assert plan("can", interface, "x", None).interface == "udp_multicast"


def test_a_named_udp_port_and_interface_local_group_are_kept() -> None:
    spec = plan("can", "udp_multicast", "ff01::1:2", 47123)
    assert (spec.channel, spec.udp_port) == ("ff01::1:2", 47123)


@pytest.mark.parametrize("group", ["ff15:7079:7468:6f6e:6465:6d6f:6d63:6173", "239.74.163.2", "ff02::1"])
def test_a_group_that_reaches_the_lan_is_refused(group: str) -> None:
    with pytest.raises(ConfigError, match="LAN") as info:
        plan("can", "udp_multicast", group, None)
    assert info.value.key == "buses.can.channel"


@pytest.mark.parametrize("interface,channel", [("pcan", "PCAN_USBBUS1"), ("kvaser", 0), ("slcan", "/dev/ttyACM0"),
                                               ("ixxat", 0), ("vector", 0), ("socketcan", "can0")])
def test_physical_interfaces_are_refused_with_the_reason(interface: str, channel: object) -> None:
    with pytest.raises(ConfigError) as info:
        plan("can", interface, channel, None)  # type: ignore[arg-type]
    text = str(info.value)
    assert "refusing" in text and "real CAN interface" in text and "vcan" in text
    assert info.value.key == "buses.can.interface"


def test_a_missing_vcan_device_says_how_to_create_it(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setattr(can_serve, "_SYS_NET", tmp_path / "net")
    with pytest.raises(ConfigError, match="ip link add dev vcan7 type vcan"):
        plan("can", "socketcan", "vcan7", None)


def test_a_present_vcan_device_is_used(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    net, virtual = tmp_path / "net", tmp_path / "virtual"
    (net / "vcan3").mkdir(parents=True)
    (net / "vcan3" / "type").write_text("280\n")
    (virtual / "vcan3").mkdir(parents=True)
    (net / "can0").mkdir()
    (net / "can0" / "type").write_text("280\n")  # a real controller: not under devices/virtual
    monkeypatch.setattr(can_serve, "_SYS_NET", net)
    monkeypatch.setattr(can_serve, "_SYS_VIRTUAL", virtual)
    assert plan("can", "socketcan", "vcan3", None) == ServedCan("socketcan", "vcan3")
    assert can_serve.is_virtual_can("can0") is False
    with pytest.raises(ConfigError, match="real CAN interface"):
        plan("can", "socketcan", "can0", None)
