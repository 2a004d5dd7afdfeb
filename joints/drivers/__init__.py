"""Drivers: register-level logic per device family (same code for hardware and emulator)."""

from __future__ import annotations

from typing import TYPE_CHECKING

from joints.drivers.base import JointDriver, RawState, Units

if TYPE_CHECKING:
    from joints.clock import Clock
    from joints.config import JointConfig


def make_driver(cfg: "JointConfig", link: object, clock: "Clock") -> JointDriver:
    """Build the driver for a configured joint on its bus link."""
    from joints.errors import ConfigError

    if cfg.device == "erob":
        from joints.devices.erob.profiles import profile
        from joints.drivers.erob_modbus import ErobModbusDriver
        from joints.link.modbus import ModbusLink

        assert isinstance(link, ModbusLink)
        prof = profile(cfg.model or "eRob80H100")
        if cfg.profile:
            prof = prof.with_overrides(**dict(cfg.profile))
        return ErobModbusDriver(link, cfg.address, profile=prof, clock=clock, name=cfg.name)
    raise ConfigError(f"no driver for device {cfg.device!r} yet", key=f"joints.{cfg.name}.device")


__all__ = ["JointDriver", "RawState", "Units", "make_driver"]
