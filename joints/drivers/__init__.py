"""Drivers: register-level logic per device family (same code for hardware and emulator)."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from joints.drivers.base import JointDriver, RawState, Units

if TYPE_CHECKING:
    from joints.clock import Clock
    from joints.config import JointConfig
    from joints.devices.erob.profiles import ErobProfile


def erob_profile(cfg: JointConfig) -> ErobProfile:
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


def hub_profile(cfg: JointConfig) -> Any:
    """The hub-motor profile of a configured ZLAC8015D wheel (``profile`` overrides applied)."""
    from joints.devices.zlac.profile import HubMotorProfile
    from joints.errors import ConfigError

    try:
        prof = HubMotorProfile()
        return prof.with_overrides(**dict(cfg.profile)) if cfg.profile else prof
    except ConfigError as exc:
        raise ConfigError(exc.message, key=f"joints.{cfg.name}.profile" + (f".{exc.key}" if exc.key else ""),
                          allowed=exc.allowed) from exc


def device_profile(cfg: JointConfig) -> Any:
    """The physical profile of a configured joint, by device."""
    return hub_profile(cfg) if cfg.device == "zlac8015d" else erob_profile(cfg)


def make_driver(cfg: JointConfig, link: object, clock: Clock, shared: dict[Any, Any] | None = None) -> JointDriver:
    """Build the driver for a configured joint on its bus link.

    ``shared`` holds per-drive objects (a ZLAC8015D's two channels share one ZlacDrive).
    """
    from joints.errors import ConfigError

    if cfg.device == "erob":
        from joints.drivers.erob_modbus import ErobModbusDriver
        from joints.link.modbus import ModbusLink

        assert isinstance(link, ModbusLink)
        return ErobModbusDriver(link, cfg.address, profile=erob_profile(cfg), clock=clock, name=cfg.name)
    if cfg.device == "zlac8015d":
        from joints.drivers.zlac_modbus import ZlacChannelDriver, ZlacDrive
        from joints.link.modbus import ModbusLink

        assert isinstance(link, ModbusLink)
        shared = {} if shared is None else shared
        key = (cfg.bus, cfg.address)
        drive = shared.get(key)
        if drive is None:
            drive = shared[key] = ZlacDrive(link, cfg.address, clock=clock, name=f"zlac8015d@{cfg.bus}:{cfg.address}")
        return ZlacChannelDriver(drive, cfg.channel or "", profile=hub_profile(cfg), name=cfg.name)
    raise ConfigError(f"no driver for device {cfg.device!r} yet", key=f"joints.{cfg.name}.device")


__all__ = ["JointDriver", "RawState", "Units", "device_profile", "erob_profile", "hub_profile", "make_driver"]
