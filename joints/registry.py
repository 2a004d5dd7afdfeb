"""The registry: the one list of bus protocols and device families, and what each brings.

Rule: nothing else in ``joints`` compares device or protocol names. Config validation, driver
creation, the simulated world, ``joints sim serve``, the CLI's ``--device`` choices and ``scan``
all ask this module. Adding a device family is one :class:`DeviceFamily` entry here plus its own
files (devices/, drivers/, sim/); adding a protocol is one :class:`BusProtocol` entry plus its
codec, link rule, parameter access and twin front. Heavy modules (drivers, twins, python-can,
pyserial, MuJoCo) are imported only when an entry is used.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from joints.errors import ConfigError

if TYPE_CHECKING:
    from joints.clock import Clock
    from joints.configtypes import BusConfig, JointConfig
    from joints.devices.params import ParamSet
    from joints.drivers.base import JointDriver
    from joints.link.base import Link

#: protocol -> (bus config, transport, clock, in-process peer for the direct path or None) -> link
LinkFactory = Callable[["BusConfig", Any, "Clock", Any], "Link[Any]"]
#: (joint config, the bus's link, clock, objects shared by the joints of one rig) -> driver
DriverFactory = Callable[["JointConfig", Any, "Clock", dict[Any, Any]], "JointDriver"]


@dataclass(frozen=True)
class BusProtocol:
    """One protocol a bus can speak."""

    name: str
    medium: str  #: "serial" (a byte stream: RS485 port, pty) or "can" (python-can frames)
    addresses: tuple[int, int]  #: joint addresses on this protocol (inclusive)
    description: str
    link: LinkFactory
    open_transport: Callable[[BusConfig], Any]  #: hardware: the bus's transport from its config
    device_bus: Callable[[BusConfig], Any]  #: sim: the emulated side of the bus (fronts attach with .add)
    #: sim: (device bus, bus config, clock) -> an in-process transport to it; without a config: untimed
    sim_transport: Callable[..., Any]
    direct: bool = False  #: the sim may skip bytes (message objects straight to the device bus)
    silence: bool = False  #: frames end with a t3.5 silence (Modbus RTU); bus timing and the planner count it
    #: ``joints scan`` of any node of the protocol: (link, addresses, listen [s]) -> a record per node found;
    #: None: the scan probes each address with the device family's driver
    scan: Callable[[Any, Sequence[int], float], Iterable[dict[str, object]]] | None = None
    sync: bool = False  #: the bus has a SYNC for cyclic modes (bus and joint key ``sync_period``)
    #: replay and plots: (address -> (joint, its family's map on this protocol), a request frame, its reply
    #: frames; frames have ``data``, ``can_id``, ``extended``) -> {"joint.parameter": value}, or None: not named
    values: Callable[[Mapping[int, tuple[str, Any]], Any, Sequence[Any]], dict[str, Any] | None] | None = None


@dataclass(frozen=True)
class DeviceFamily:
    """One family of drives: its parameters, profiles, a driver per protocol and its twin."""

    name: str
    devices: tuple[str, ...]  #: config ``device`` names of this family
    description: str
    params: Callable[[], ParamSet]
    profile: Callable[[str | None], Any]  #: variant name (None = default) -> physical profile
    drivers: Mapping[str, DriverFactory]  #: protocol -> driver factory
    #: protocol -> its parameter map (what ``joints registers`` lists: rows of address/name/type/access/unit)
    tables: Mapping[str, Callable[[], Any]]
    channels: tuple[str, ...] = ()  #: a multi-motor drive's channel names (joint key ``channel``)
    #: protocol -> (lo, hi) joint addresses where the family narrows the protocol's range
    addresses: Mapping[str, tuple[int, int]] = field(default_factory=dict)
    #: sim: (joint specs of one drive, their inertia) -> (the twin of that drive, channel -> stepper)
    twin: Callable[[Sequence[Any], Mapping[str, float]], tuple[Any, Mapping[Any, Any]]] | None = None
    #: sim: protocol -> (twin, address) -> the object that answers that protocol's frames for it
    fronts: Mapping[str, Callable[[Any, int], Any]] = field(default_factory=dict)
    #: the communication watchdog armed while a joint is enabled [ms] unless its config says otherwise
    watchdog_ms: int | None = None
    #: device name -> its profile's model when the config names none (one family, several devices)
    device_models: Mapping[str, str] = field(default_factory=dict)
    #: the status parameter ``joints scan`` reads to find a drive (every protocol of the family reaches it)
    scan_param: str = "error_code"
    #: protocol -> the operating modes a joint may name (joint key ``mode``; the first is the default)
    modes: Mapping[str, tuple[str, ...]] = field(default_factory=dict)
    #: identity and line settings (address, node id, baud rate, protocol switch): ``joints params load``/``diff``
    #: leave them out unless asked (``--include-identity --confirm``)
    identity_params: tuple[str, ...] = ()
    #: run-time set-points, control words and save triggers: dumped as read, never loaded (they act)
    live_params: tuple[str, ...] = ()
    #: the parameters that select the drive's operating mode (one-shot commands restore what they found)
    mode_params: tuple[str, ...] = ()
    #: the key parameters ``joints info`` shows (limits, gains, mode, watchdog, line settings), where the
    #: joint's protocol reaches and can read them
    info_params: tuple[str, ...] = ()
    #: protocol -> the electronic data sheet of the family's twin on it for a node id (CANopen: an EDS,
    #: CiA 306; ``joints sim eds``)
    eds: Mapping[str, Callable[[int], str]] = field(default_factory=dict)

    @property
    def protocols(self) -> tuple[str, ...]:
        return tuple(self.drivers)

    def address_range(self, protocol: str) -> tuple[int, int]:
        return self.addresses.get(protocol) or PROTOCOLS[protocol].addresses

    def config_profile(self, cfg: JointConfig) -> Any:
        """The profile of a configured joint (``model`` + ``profile`` overrides); errors name the joint's key."""
        key = f"joints.{cfg.name}.model"
        try:
            own = self.device_models.get(cfg.device)
            prof = self.profile(cfg.model or own)
            if cfg.model and own and prof != self.profile(own):
                raise ConfigError(f"model {cfg.model!r} is not a {cfg.device} (that is {own!r})", key="",
                                  allowed=(own,))
            if cfg.profile:
                key = f"joints.{cfg.name}.profile"
                prof = prof.with_overrides(**dict(cfg.profile))
        except ConfigError as exc:
            if exc.key and key.endswith(".profile"):
                key += f".{exc.key}"
            raise ConfigError(exc.message, key=key, allowed=exc.allowed) from exc
        return prof

    def firmware_profile(self, firmware: str | None = None) -> Any:
        """The firmware profile (its quirks, :mod:`joints.devices.quirks`) a joint's ``firmware`` key names."""
        from joints.devices.quirks import firmware_profile

        return firmware_profile(self.name, firmware)

    def quirks(self, cfg: JointConfig) -> frozenset[str]:
        """The quirks of a configured joint's firmware (its driver works around them, its twin has them)."""
        try:
            return frozenset(self.firmware_profile(cfg.firmware).quirks)
        except ConfigError as exc:
            raise ConfigError(exc.message, key=f"joints.{cfg.name}.firmware", allowed=exc.allowed) from exc

    def driver(self, cfg: JointConfig, link: Any, clock: Clock, shared: dict[Any, Any], protocol: str) -> JointDriver:
        try:
            make = self.drivers[protocol]
        except KeyError:
            raise ConfigError(f"device {cfg.device!r} has no driver for protocol {protocol!r} yet",
                              key=f"joints.{cfg.name}.device", allowed=pairs()) from None
        return make(cfg, link, clock, shared)

    # the world's view of a family (joints.sim.world.TwinMaker)
    def build_twin(self, specs: Sequence[Any], inertia: Mapping[str, float]) -> tuple[Any, Mapping[Any, Any]]:
        if self.twin is None:
            raise ConfigError(f"device {specs[0].device!r} has no simulated twin yet", key=f"joints.{specs[0].name}.device")
        return self.twin(specs, inertia)

    def front(self, protocol: str, twin: Any, address: int) -> Any:
        try:
            make = self.fronts[protocol]
        except KeyError:
            raise ConfigError(f"the {self.name} twin cannot be reached over {protocol!r} yet",
                              key="buses", allowed=sorted(self.fronts)) from None
        return make(twin, address)


# --- protocols ----------------------------------------------------------------------------------


def _modbus_link(cfg: BusConfig, transport: Any, clock: Clock, peer: Any) -> Link[Any]:
    from joints.link.base import RetryPolicy
    from joints.link.modbus import ModbusLink

    return ModbusLink(transport, peer=peer, policy=RetryPolicy(timeout=cfg.timeout, retries=cfg.retries),
                      echo=cfg.echo, clock=clock, name=cfg.name)


def _serial_transport(cfg: BusConfig) -> Any:
    from joints.transports.serial import SerialTransport

    if cfg.port is None:  # e.g. a sim config opened with backend="hardware"
        raise ConfigError("is required for backend = \"hardware\" (e.g. \"/dev/ttyUSB0\")", key=f"buses.{cfg.name}.port")
    return SerialTransport(cfg.port, cfg.baudrate, parity=cfg.parity, stopbits=cfg.stopbits,
                           gap=None if protocol(cfg.protocol).silence else 0.0)


def _modbus_device_bus(cfg: BusConfig) -> Any:
    from joints.sim.modbus_front import ModbusDeviceBus

    return ModbusDeviceBus()


# --- bus timing (issue 29; docs/timing.md) -------------------------------------------------------

#: s of host adapter latency per transaction when a bus config gives no ``adapter_latency``, per medium.
#: serial: USB-serial adapters (FTDI, CH340, CP210x) are USB full-speed devices: the host polls them once per
#: 1 ms frame (FTDI's latency timer at its 1 ms minimum); a real ZLAC8015D log shows 1.8 ms per transaction
#: beyond bytes and t3.5, of which this is the adapter's share (the drive's turnaround the rest).
#: can: EST 0.2 ms, the receive path of a CAN controller to a Linux SocketCAN socket (interrupt, softirq,
#: socket wake-up); USB-CAN adapters on full-speed USB take up to 1 ms more: measure it (``joints bench
#: --hardware``) and set ``adapter_latency``.
ADAPTER_LATENCY: dict[str, float] = {"serial": 0.001, "can": 0.0002}


def adapter_latency(cfg: BusConfig) -> float:
    """The host adapter's latency per transaction on a configured bus [s] (0 with ``timing = "ideal"``)."""
    if cfg.timing == "ideal":
        return 0.0
    if cfg.adapter_latency is not None:
        return float(cfg.adapter_latency)
    return ADAPTER_LATENCY[protocol(cfg.protocol).medium]


def _serial_line(device_bus: Any, config: BusConfig | None = None, clock: Any = None) -> Any:
    """Sim: a timed RS485 line to the device bus (``timing = "wire"``), or an instant loopback (``"ideal"``,
    or no config: test harnesses)."""
    from joints.transports.loopback import LoopbackTransport

    if config is None or clock is None or config.timing == "ideal":
        return LoopbackTransport(device_bus)
    from joints.transports.serial_sim import TimedSerialLine
    from joints.transports.serial_timing import char_bits, t35_bits

    bits = char_bits(config.parity, config.stopbits)
    gap = t35_bits(config.baudrate, config.parity, config.stopbits) / config.baudrate \
        if protocol(config.protocol).silence else 0.0
    return TimedSerialLine(device_bus, baudrate=config.baudrate, clock=clock, adapter_latency=adapter_latency(config),
                           gap=gap, bits_per_char=bits)


def _erob_can_link(cfg: BusConfig, transport: Any, clock: Clock, peer: Any) -> Link[Any]:
    from joints.devices.erob.can import describe_error_reply
    from joints.link.base import RetryPolicy
    from joints.link.erob_can import ErobCanLink

    def error_text(code: int) -> tuple[str, str]:
        info = describe_error_reply(code)
        return info.text, info.hint

    return ErobCanLink(transport, policy=RetryPolicy(timeout=cfg.timeout, retries=cfg.retries), clock=clock,
                       name=cfg.name, error_text=error_text)


def _can_transport(cfg: BusConfig) -> Any:
    from joints.transports.can import PythonCanTransport

    if cfg.interface is None:  # e.g. a sim config opened with backend="hardware"
        raise ConfigError("is required for backend = \"hardware\" (e.g. \"socketcan\", \"pcan\", \"udp_multicast\")",
                          key=f"buses.{cfg.name}.interface")
    settings: dict[str, Any] = {} if cfg.udp_port is None else {"port": cfg.udp_port}
    return PythonCanTransport.open(cfg.interface, cfg.channel, cfg.bitrate, **settings)


def _erob_can_device_bus(cfg: BusConfig) -> Any:
    from joints.sim.erob_can import ErobCanBus

    return ErobCanBus(name=cfg.name, bitrate=cfg.bitrate, ideal=cfg.timing == "ideal")


def _canopen_link(cfg: BusConfig, transport: Any, clock: Clock, peer: Any) -> Link[Any]:
    from joints.link.base import RetryPolicy
    from joints.link.canopen import CanopenLink
    from joints.transports.can import PythonCanTransport
    from joints.transports.can_sim import LockstepCanBus

    sim = isinstance(transport, PythonCanTransport) and isinstance(transport.bus, LockstepCanBus)
    link = CanopenLink(transport, policy=RetryPolicy(timeout=cfg.timeout, retries=cfg.retries), clock=clock,
                       name=cfg.name, bus_clock=sim)
    link.sync_period = cfg.sync_period
    link.bitrate = cfg.bitrate
    return link


def _canopen_device_bus(cfg: BusConfig) -> Any:
    from joints.sim.erob_canopen import ErobCanopenBus

    return ErobCanopenBus(name=cfg.name, bitrate=cfg.bitrate, ideal=cfg.timing == "ideal")


def _canopen_scan(link: Any, addresses: Sequence[int], listen: float) -> Iterable[dict[str, object]]:
    from joints.drivers.canopen_scan import scan

    return scan(link, addresses, listen=listen)


def _lockstep_can(device_bus: Any, config: BusConfig | None = None, clock: Any = None) -> Any:
    """Sim: a python-can node on the device bus's timed medium (the host adapter's latency from the config)."""
    from joints.transports.can import PythonCanTransport
    from joints.transports.can_sim import LockstepCanBus

    latency = 0.0 if config is None else adapter_latency(config)
    return PythonCanTransport(LockstepCanBus(medium=device_bus.medium, adapter_latency=latency))


def _mks_link(cfg: BusConfig, transport: Any, clock: Clock, peer: Any) -> Link[Any]:
    from joints.link.base import RetryPolicy
    from joints.link.mks import MksLink

    return MksLink(transport, policy=RetryPolicy(timeout=cfg.timeout, retries=cfg.retries), echo=cfg.echo,
                   clock=clock, name=cfg.name)


def _mks_device_bus(cfg: BusConfig) -> Any:
    from joints.sim.mks_front import MksDeviceBus

    return MksDeviceBus()


def _modbus_values(tables: Mapping[int, tuple[str, Any]], request: Any, replies: Sequence[Any]) -> dict[str, Any] | None:
    from joints.drivers.exchange import modbus_values

    return modbus_values(tables, request, replies)


def _erob_can_values(tables: Mapping[int, tuple[str, Any]], request: Any, replies: Sequence[Any]) -> dict[str, Any] | None:
    from joints.drivers.exchange import erob_can_values

    return erob_can_values(tables, request, replies)


PROTOCOLS: dict[str, BusProtocol] = {
    "modbus-rtu": BusProtocol(
        name="modbus-rtu", medium="serial", addresses=(1, 247),
        description="Modbus RTU over RS485 (FC03/04/06/16)",
        link=_modbus_link, open_transport=_serial_transport, device_bus=_modbus_device_bus,
        sim_transport=_serial_line, direct=True, silence=True, values=_modbus_values,
    ),
    "erob-can": BusProtocol(
        name="erob-can", medium="can", addresses=(1, 127),
        description="ZeroErr eRob CAN custom protocol (requests 0x640+node, replies 0x5C0+node; 1 Mbit/s)",
        link=_erob_can_link, open_transport=_can_transport, device_bus=_erob_can_device_bus,
        sim_transport=_lockstep_can, values=_erob_can_values,
    ),
    "mks-serial": BusProtocol(
        name="mks-serial", medium="serial", addresses=(1, 255),
        description="MKS SERVO42D/57D native RS485 protocol (0xFA/0xFB/0xFC, checksum-8, completion frames)",
        link=_mks_link, open_transport=_serial_transport, device_bus=_mks_device_bus,
        sim_transport=_serial_line, direct=False,  # completion frames come unasked: the byte path only
    ),
    "canopen": BusProtocol(
        name="canopen", medium="can", addresses=(1, 127),
        description="CANopen CiA 301/402 (SDO 0x600/0x580+node, PDOs, SYNC, NMT, heartbeat)",
        link=_canopen_link, open_transport=_can_transport, device_bus=_canopen_device_bus,
        sim_transport=_lockstep_can, scan=_canopen_scan, sync=True,
    ),
}


# --- device families ----------------------------------------------------------------------------


def _erob_params() -> ParamSet:
    from joints.devices.erob.params import EROB_PARAMS

    return EROB_PARAMS


def _erob_profile(model: str | None) -> Any:
    from joints.devices.erob.profiles import DEFAULT_MODEL, profile

    return profile(model or DEFAULT_MODEL)


def _erob_modbus_driver(cfg: JointConfig, link: Any, clock: Clock, shared: dict[Any, Any]) -> JointDriver:
    from joints.drivers.erob_modbus import ErobModbusDriver

    return ErobModbusDriver(link, cfg.address, profile=FAMILIES["erob"].config_profile(cfg), clock=clock,
                            name=cfg.name)


def _erob_can_driver(cfg: JointConfig, link: Any, clock: Clock, shared: dict[Any, Any]) -> JointDriver:
    from joints.drivers.erob_can import ErobCanDriver

    return ErobCanDriver(link, cfg.address, profile=FAMILIES["erob"].config_profile(cfg), clock=clock,
                         name=cfg.name)


def _erob_canopen_driver(cfg: JointConfig, link: Any, clock: Clock, shared: dict[Any, Any]) -> JointDriver:
    from joints.drivers.erob_canopen import ErobCanopenDriver, SyncCycle

    period = cfg.sync_period or link.sync_period or 0.001
    cycle = SyncCycle.of(link, period)  # the bus's, held by its link
    return ErobCanopenDriver(link, cfg.address, profile=FAMILIES["erob"].config_profile(cfg), clock=clock,
                             name=cfg.name, mode=cfg.mode, sync_period=cycle.period, cycle=cycle, eds=cfg.eds)


def _erob_canopen_table() -> Any:
    from joints.devices.erob.canopen import EROB_CANOPEN

    return EROB_CANOPEN


def _erob_canopen_front(twin: Any, address: int) -> Any:
    from joints.sim.erob_canopen import CanopenFront

    return CanopenFront(twin, address)


def _erob_eds(node: int) -> str:
    from joints.devices.erob.eds import eds_text
    from joints.devices.erob.profiles import DEFAULT_MODEL, PROFILES
    from joints.sim.erob import power_on_defaults

    return eds_text(node, power_on_defaults(PROFILES[DEFAULT_MODEL], node))


def _erob_can_table() -> Any:
    from joints.devices.erob.can import EROB_CAN

    return EROB_CAN


def _erob_can_front(twin: Any, address: int) -> Any:
    from joints.sim.erob_can import ErobCanFront

    return ErobCanFront(twin)


def _erob_modbus_table() -> Any:
    from joints.devices.erob.registers import EROB_MODBUS

    return EROB_MODBUS


def _erob_twin(specs: Sequence[Any], inertia: Mapping[str, float]) -> tuple[Any, Mapping[Any, Any]]:
    from joints.sim.erob import ErobFirmware
    from joints.sim.erob_can import identify_twin

    d = specs[0]
    twin = ErobFirmware(d.profile, d.address, inertia=inertia[d.name],
                        quirks=frozenset(FAMILIES["erob"].firmware_profile(d.extra.get("firmware")).quirks))
    identify_twin(twin, d.profile.model, d.address)  # CAN node id, module information (7.5.3)
    return twin, {None: twin}


def _erob_modbus_front(twin: Any, address: int) -> Any:
    from joints.devices.erob.registers import EROB_MODBUS
    from joints.sim.modbus_front import ModbusFront

    return ModbusFront(twin, EROB_MODBUS, node_id="modbus_address")


def _zlac_params() -> ParamSet:
    from joints.devices.zlac.registers import ZLAC8015D

    return ZLAC8015D.params


def _zlac_profile(model: str | None) -> Any:
    from joints.devices.zlac.profile import DEFAULT_MODEL, profile

    return profile(model or DEFAULT_MODEL)


def _zlac_modbus_driver(cfg: JointConfig, link: Any, clock: Clock, shared: dict[Any, Any]) -> JointDriver:
    from joints.drivers.zlac_modbus import ZlacChannelDriver, ZlacDrive

    key = ("zlac8015d", cfg.bus, cfg.address)
    drive = shared.get(key)
    quirks = FAMILIES["zlac8015d"].quirks(cfg)
    if drive is None:
        drive = shared[key] = ZlacDrive(link, cfg.address, clock=clock, name=f"zlac8015d@{cfg.bus}:{cfg.address}",
                                        quirks=quirks)
    elif drive.quirks != quirks:
        raise ConfigError("both channels of one drive run one firmware: give them the same firmware key",
                          key=f"joints.{cfg.name}.firmware")
    lines = cfg.profile.get("encoder_lines")  # named by the config, else the drive's setting (read at connect)
    return ZlacChannelDriver(drive, cfg.channel or "", profile=FAMILIES["zlac8015d"].config_profile(cfg),
                             name=cfg.name, encoder_lines=None if lines is None else int(lines))


def _zlac_modbus_table() -> Any:
    from joints.devices.zlac.registers import ZLAC8015D

    return ZLAC8015D


def _zlac_twin(specs: Sequence[Any], inertia: Mapping[str, float]) -> tuple[Any, Mapping[Any, Any]]:
    from joints.sim.zlac import ZlacFirmware

    by_channel = {s.channel: s for s in specs}
    twin = ZlacFirmware(
        specs[0].profile, specs[0].address,
        inertia_left=inertia[by_channel["left"].name] if "left" in by_channel else None,
        inertia_right=inertia[by_channel["right"].name] if "right" in by_channel else None,
        quirks=frozenset(FAMILIES["zlac8015d"].firmware_profile(specs[0].extra.get("firmware")).quirks),
    )
    return twin, {"left": twin.left, "right": twin.right}


def _zlac_modbus_front(twin: Any, address: int) -> Any:
    from joints.devices.zlac.registers import ZLAC8015D
    from joints.sim.modbus_front import ModbusFront

    return ModbusFront(twin, ZLAC8015D, node_id="rs485_node_id")


def _mks_params() -> ParamSet:
    from joints.devices.mks.params import MKS_PARAMS

    return MKS_PARAMS


def _mks_profile(model: str | None) -> Any:
    from joints.devices.mks.profile import DEFAULT_MODEL, profile

    return profile(model or DEFAULT_MODEL)


def _mks_native_driver(cfg: JointConfig, link: Any, clock: Clock, shared: dict[Any, Any]) -> JointDriver:
    from joints.devices.quirks import MKS_HEARTBEAT
    from joints.drivers.mks_native import MksNativeDriver, MksNativeHeartbeatDriver

    fw = FAMILIES["mks"].firmware_profile(cfg.firmware)  # V1.0.9's heartbeat: the watchdog capability
    cls = MksNativeHeartbeatDriver if MKS_HEARTBEAT in fw.features else MksNativeDriver
    return cls(link, cfg.address, device=cfg.device, profile=FAMILIES["mks"].config_profile(cfg),
               clock=clock, name=cfg.name, firmware=fw)


def _mks_modbus_driver(cfg: JointConfig, link: Any, clock: Clock, shared: dict[Any, Any]) -> JointDriver:
    from joints.devices.quirks import MKS_HEARTBEAT
    from joints.drivers.mks_modbus import MksModbusDriver, MksModbusHeartbeatDriver

    fw = FAMILIES["mks"].firmware_profile(cfg.firmware)
    cls = MksModbusHeartbeatDriver if MKS_HEARTBEAT in fw.features else MksModbusDriver
    return cls(link, cfg.address, device=cfg.device, profile=FAMILIES["mks"].config_profile(cfg),
               clock=clock, name=cfg.name, firmware=fw)


def _mks_native_table() -> Any:
    from joints.devices.mks.tables import native_rows

    return native_rows()


def _mks_modbus_table() -> Any:
    from joints.devices.mks.tables import modbus_rows

    return modbus_rows()


def _mks_twin(specs: Sequence[Any], inertia: Mapping[str, float]) -> tuple[Any, Mapping[Any, Any]]:
    from joints.devices.mks.params import model_params
    from joints.sim.mks import MksFirmware

    d = specs[0]
    twin = MksFirmware(d.profile, model_params(d.device), d.address, inertia=inertia[d.name],
                       modbus=d.protocol == "modbus-rtu",
                       firmware=FAMILIES["mks"].firmware_profile(d.extra.get("firmware")))
    return twin, {None: twin}


def _mks_native_front(twin: Any, address: int) -> Any:
    from joints.sim.mks_front import MksNativeFront

    return MksNativeFront(twin)


def _mks_modbus_front(twin: Any, address: int) -> Any:
    from joints.sim.mks_modbus_front import MksModbusFront

    return MksModbusFront(twin)


FAMILIES: dict[str, DeviceFamily] = {
    "erob": DeviceFamily(
        name="erob", devices=("erob",),
        description="ZeroErr eRob rotary actuator (70/80/90/110/142, ratios 50-160)",
        params=_erob_params, profile=_erob_profile,
        drivers={"modbus-rtu": _erob_modbus_driver, "erob-can": _erob_can_driver, "canopen": _erob_canopen_driver},
        tables={"modbus-rtu": _erob_modbus_table, "erob-can": _erob_can_table, "canopen": _erob_canopen_table},
        twin=_erob_twin,
        fronts={"modbus-rtu": _erob_modbus_front, "erob-can": _erob_can_front, "canopen": _erob_canopen_front},
        eds={"canopen": _erob_eds},
        watchdog_ms=1000,  # off at power-on (0x0002 = 0): armed while enabled, restored on disable
        modes={"canopen": ("pp", "pv", "pt", "csp", "csv", "cst", "ip")},
        identity_params=("modbus_address", "modbus_baud_rate", "can_address", "can_baud_rate"),
        live_params=("target_absolute_position", "target_relative_position", "target_current", "target_speed",
                     "target_torque", "controlword", "modes_of_operation", "interpolation_data_record_1",
                     "analog_quantity_value", "use_bus_to_tune_pid"),
        mode_params=("operation_mode", "motion_mode", "modes_of_operation"),
        info_params=("modbus_address", "modbus_baud_rate", "can_address", "can_baud_rate",
                     "modbus_communication_timeout_duration", "producer_heartbeat_time", "operation_mode",
                     "motion_mode", "modes_of_operation_display", "control_source", "position_loop_gain",
                     "speed_loop_gain", "speed_loop_integral", "min_position_limit_value", "max_position_limit_value",
                     "max_speed", "max_acceleration", "continuous_current", "peak_current", "max_motor_current",
                     "max_position_error", "profile_speed", "profile_acceleration", "profile_deceleration",
                     "bus_voltage", "error_code"),
    ),
    "zlac8015d": DeviceFamily(
        name="zlac8015d", devices=("zlac8015d",),
        description="ZLAC8015D dual-channel hub servo driver (two hub motors, left/right)",
        params=_zlac_params, profile=_zlac_profile,
        drivers={"modbus-rtu": _zlac_modbus_driver},
        tables={"modbus-rtu": _zlac_modbus_table},
        channels=("left", "right"), addresses={"modbus-rtu": (1, 127)},
        twin=_zlac_twin, fronts={"modbus-rtu": _zlac_modbus_front},
        watchdog_ms=1000,  # the drive's own default offline time (0x2000)
        scan_param="software_version",  # 0x20A0: the eRob map has no such register (scan tells them apart)
        identity_params=("rs485_node_id", "rs485_baud_rate", "can_node_id", "can_baud_rate"),
        live_params=("control_word", "target_velocity_left", "target_velocity_right", "target_position_left",
                     "target_position_right", "target_torque_left", "target_torque_right", "clear_feedback_position",
                     "in_absolute_position_control_reset_the_zero_point", "whether_store_rw_register_to_eeprom"),
        mode_params=("control_mode", "synchronous_asynchronous_control_status"),
        info_params=("software_version", "rs485_node_id", "rs485_baud_rate", "communication_offline_time",
                     "control_mode", "synchronous_asynchronous_control_status", "maximum_motor_speed",
                     "rated_current_left", "maximum_current_left", "rated_current_right", "maximum_current_right",
                     "pl_kp_left", "vl_kp_left", "vl_ki_left", "pl_kp_right", "vl_kp_right", "vl_ki_right",
                     "dc_voltage", "motor_temperature", "error_code_left", "error_code_right"),
    ),
    "mks": DeviceFamily(
        name="mks", devices=("mks-servo42d", "mks-servo57d"),
        description="MKS SERVO42D (NEMA17) / SERVO57D (NEMA23) closed-loop stepper drives; communication watchdog "
                    "(heartbeat 0x98) from firmware V1.0.9 only",
        params=_mks_params, profile=_mks_profile,
        drivers={"mks-serial": _mks_native_driver, "modbus-rtu": _mks_modbus_driver},
        tables={"mks-serial": _mks_native_table, "modbus-rtu": _mks_modbus_table},
        addresses={"mks-serial": (1, 255), "modbus-rtu": (1, 247)},
        twin=_mks_twin, fronts={"mks-serial": _mks_native_front, "modbus-rtu": _mks_modbus_front},
        device_models={"mks-servo42d": "SERVO42D", "mks-servo57d": "SERVO57D"},
        watchdog_ms=1000,  # V1.0.9 heartbeat protection (0x98, off at power-on): armed while enabled; older: none
        scan_param="motor_status",  # 0xF1: the MKS reports no error code
        identity_params=("slave_address", "baud_rate", "modbus_rtu", "group_address", "slave_respond",
                         "slave_active"),
        live_params=("motor_enable",),
        mode_params=("work_mode",),  # write-only: a one-shot cannot read it back
        info_params=("en_pin_status", "protection_state", "motor_status", "go_back_to_zero_status", "io_status",
                     "work_mode", "working_current", "microsteps", "baud_rate", "slave_address"),
    ),
}

#: the config names users may write but no entry serves yet (a clear "not yet" instead of "unknown")
PLANNED_DEVICES: tuple[str, ...] = ()
PLANNED_PROTOCOLS: tuple[str, ...] = ()


# --- queries ----------------------------------------------------------------------------------


def devices() -> tuple[str, ...]:
    """Every config ``device`` name with an entry."""
    return tuple(d for f in FAMILIES.values() for d in f.devices)


def protocols() -> tuple[str, ...]:
    return tuple(PROTOCOLS)


def default_protocol(medium: str) -> str:
    """The protocol assumed on a bare port (``medium`` "serial") or CAN interface ("can"): the first of
    that medium in registry order."""
    return next(p.name for p in PROTOCOLS.values() if p.medium == medium)


def pairs() -> list[str]:
    """"device on protocol" for every pair that has a driver."""
    return sorted(f"{d} on {p}" for f in FAMILIES.values() for d in f.devices for p in f.drivers)


def families(protocol: str) -> tuple[DeviceFamily, ...]:
    """The families with a driver for ``protocol``, in registry order.

    ``joints scan`` probes a bus address with each family's :attr:`DeviceFamily.scan_param` in
    this order and takes the first that answers, so an earlier family's probe must be refused by
    the later families' drives (eRob FC03 0x0060, then ZLAC FC03 0x20A0, then MKS FC04 0xF1).
    """
    return tuple(f for f in FAMILIES.values() if protocol in f.drivers)


def family(device: str, *, key: str = "device") -> DeviceFamily:
    """The family of a config ``device`` name (a :class:`ConfigError` listing the known ones otherwise)."""
    for f in FAMILIES.values():
        if device in f.devices:
            return f
    if device in PLANNED_DEVICES:
        raise ConfigError(f"device {device!r} is not supported yet", key=key, allowed=devices())
    raise ConfigError(f"{device!r} is not a device", key=key, allowed=devices())


def protocol(name: str, *, key: str = "protocol") -> BusProtocol:
    try:
        return PROTOCOLS[name]
    except KeyError:
        what = "is not supported yet" if name in PLANNED_PROTOCOLS else "is not a protocol"
        raise ConfigError(f"{name!r} {what}", key=key, allowed=protocols()) from None
