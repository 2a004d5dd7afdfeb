"""Drivers: register-level logic per device family (same code for hardware and emulator)."""

from __future__ import annotations

from typing import TYPE_CHECKING

from joints.drivers.base import JointDriver, RawState, Units

if TYPE_CHECKING:
    from joints.clock import Clock
    from joints.config import JointConfig
    from joints.devices.erob.profiles import ErobProfile


def erob_profile(cfg: "JointConfig") -> "ErobProfile":
    """The device profile of a configured eRob joint (``model`` + ``profile`` overrides).

    Errors name the joint's key (``joints.<name>.model`` / ``joints.<name>.profile.<field>``).
    """
    from joints.devices.erob.profiles import DEFAULT_MODEL, profile
    from joints.errors import ConfigError

    key = f"joints.{cfg.name}.model"
    try:
        prof = profile(cfg.model or DEFAULT_MODEL)
        if cfg.profile:
            key = f"joints.{cfg.name}.profile"
            prof = prof.with_overrides(**dict(cfg.profile))
    except ConfigError as exc:  # name the joint's key, not the bare profile field
        if exc.key and key.endswith(".profile"):
            key += f".{exc.key}"
        raise ConfigError(exc.message, key=key, allowed=exc.allowed) from exc
    return prof


def make_driver(cfg: "JointConfig", link: object, clock: "Clock") -> JointDriver:
    """Build the driver for a configured joint on its bus link."""
    from joints.errors import ConfigError

    if cfg.device == "erob":
        from joints.drivers.erob_modbus import ErobModbusDriver
        from joints.link.modbus import ModbusLink

        assert isinstance(link, ModbusLink)
        return ErobModbusDriver(link, cfg.address, profile=erob_profile(cfg), clock=clock, name=cfg.name)
    raise ConfigError(f"no driver for device {cfg.device!r} yet", key=f"joints.{cfg.name}.device")


__all__ = ["JointDriver", "RawState", "Units", "erob_profile", "make_driver"]
