"""Config keys of CAN buses (erob-can): interface, channel, bitrate, udp_port; node ids."""

from __future__ import annotations

import copy
from typing import Any

import pytest

from joints.config import parse
from joints.errors import ConfigError


def can_cfg(backend: str = "hardware", **bus: Any) -> dict[str, Any]:
    return copy.deepcopy({
        "backend": backend,
        "buses": {"can": {"protocol": "erob-can", **bus}},
        "joints": {"shoulder": {"device": "erob", "bus": "can", "address": 5}},
    })


@pytest.fixture(autouse=True)
def _no_backend_env(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("JOINTS_BACKEND", raising=False)


def test_hardware_can_bus_keys() -> None:
    cfg = parse(can_cfg(interface="udp_multicast", channel="ff01::1", udp_port=47000))
    bus = cfg.buses["can"]
    assert (bus.interface, bus.channel, bus.udp_port, bus.bitrate) == ("udp_multicast", "ff01::1", 47000, 1_000_000)
    assert parse(can_cfg(interface="kvaser", channel=0)).buses["can"].channel == 0


def test_hardware_can_bus_needs_an_interface() -> None:
    with pytest.raises(ConfigError) as info:
        parse(can_cfg())
    assert info.value.key == "buses.can.interface" and "socketcan" in str(info.value)
    parse(can_cfg(backend="sim"))  # the sim needs none


@pytest.mark.parametrize("bus,key", [({"interface": "socketcan", "channel": "can0", "udp_port": 4000}, "udp_port"),
                                     ({"interface": "udp_multicast", "udp_port": 70000}, "udp_port"),
                                     ({"interface": 5}, "interface"),
                                     ({"interface": "socketcan", "channel": True}, "channel")])
def test_bad_can_keys_name_the_key(bus: dict[str, Any], key: str) -> None:
    with pytest.raises(ConfigError) as info:
        parse(can_cfg(**bus))
    assert info.value.key == f"buses.can.{key}"


def test_node_ids_are_1_to_127() -> None:
    data = can_cfg(backend="sim")
    data["joints"]["shoulder"]["address"] = 128
    with pytest.raises(ConfigError) as info:
        parse(data)
    assert info.value.key == "joints.shoulder.address" and "1..127" in str(info.value)


def test_a_device_without_a_can_driver_is_not_supported_on_erob_can() -> None:
    data = can_cfg(backend="sim")
    data["joints"]["shoulder"].update(device="zlac8015d", channel="left")
    with pytest.raises(ConfigError, match="'zlac8015d' on protocol 'erob-can' is not supported yet"):
        parse(data)
