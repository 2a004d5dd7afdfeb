"""ZeroErr eRob over CANopen CiA 402 (eRunner manual v1.7 chapter 5): objects by SDO, motion by PDO.

Rule: parameters travel as objects of :data:`~joints.devices.erob.canopen.EROB_CANOPEN` by SDO
(:class:`CanopenAccess`); motion is the CiA 402 state machine (:mod:`joints.devices.cia402`) driven
by RPDO1 = controlword + the mode's target (eRunner's mapping, E5) and read back from TPDO1 =
statusword + position (+ TPDO2 = velocity + current in the profile modes), all sent on SYNC: a
state read is one SYNC and that cycle's TPDOs. Same ``Joint`` API and units as the Modbus eRob.

Bring-up (chapter 5's sequence, figs 5-5 .. 5-38): NMT stop, NMT reset communication (wait for
the boot-up), 0x6060 mode and a read of 0x6061, [cyclic: 0x1005 = 0x80, 0x1006 = period; IP:
0x60C2], TPDO and RPDO mapping (only the SDOs that change the power-on mapping), heartbeat 0x1017,
NMT start. A mode change disables first (the drive refuses 0x6060 in OPERATION ENABLED with
0x08000022) and repeats the bring-up; the joint is enabled again if it was.

Modes (config ``mode``): ``pp`` (the default; ``move_to``: target + new set-point with change
set immediately, wait for the set-point acknowledge, clear bit 4 - the joints of a bus moved together,
:meth:`joints.rig.Rig.move_together`, share the acknowledge's SYNC; target reached = bit 10),
``pv`` (``set_velocity``), ``pt`` (``set_torque``: 0x6071 in per mille of rated torque), and the
cyclic ``csp``, ``csv``, ``cst``, ``ip``, driven by :meth:`joints.rig.Rig.cycle` through
:class:`SyncCycle` (one RPDO per joint and one SYNC per bus per cycle; ``sync_period``).
``move_to``/``set_velocity``/``set_torque`` switch to PP/PV/PT when the joint is in another mode.

What a state (:class:`~joints.drivers.base.RawState`) contains. Profile modes (``state()``: one
SYNC, that cycle's TPDO1 + TPDO2): statusword, position, velocity 0x606C and current 0x6078 as
the drive measured them at the SYNC, and the temperature 0x22A2 (degC, read by SDO at most every
:data:`TEMPERATURE_PERIOD`). Cyclic modes (``Rig.cycle``: the cycle's TPDO1 only, to keep
the bus load down): statusword and position at the SYNC; velocity = the position difference of
the last two cycles over their time; current 0x6078 from TPDO1 when the bus has room for 8-byte
TPDOs (:meth:`SyncCycle.feedback_tpdo`: every cyclic joint of the bus at the SYNC period fits
with worst-case stuffing; e.g. up to 3 joints at 1 kHz on 1 Mbit/s), else NaN; the temperature
as state() last read it (no SDO in the cycle; NaN before the first state()).

Safety and liveness: the host consumes each node's heartbeat (0x1017 = 100 ms, consumer time
250 ms, armed at the first heartbeat); a silent node is a fault (:data:`NODE_LOST`). The
communication watchdog of the joint is life guarding (0x100C guard time x 0x100D factor 4 = the
watchdog time; heartbeat off meanwhile, CiA 301): the host guards the node at every state read.
Quick stop = controlword 0x0002; fault reset = rising bit 7; an EMCY is the drive's fault
(code = the eRob error code, by name). Software position limits go to 0x607D and the speed limit
to 0x6080 (volatile); a torque limit stays host-side (no max current object in ZeroErr's EDS: a warning).
"""

from __future__ import annotations

import functools
import logging
import math
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

from joints.clock import Clock
from joints.codecs import canopen as co
from joints.devices import cia402
from joints.devices.cia402 import Mode, State
from joints.devices.erob import faults
from joints.devices.erob.canopen import (
    CYCLIC_TPDO1_CURRENT,
    EROB_CANOPEN,
    ERUNNER_RPDO1,
    ERUNNER_TPDOS,
    CanopenObject,
    PdoConfig,
)
from joints.devices.erob.params import EROB_PARAMS
from joints.devices.erob.profiles import ErobProfile
from joints.devices.faults import DEFINED_BY_JOINTS, Fault
from joints.devices.params import ParamMap
from joints.drivers.base import RawState
from joints.drivers.canopen_access import CanopenAccess, map_from_eds
from joints.drivers.canopen_sync import NODE_LOST, SyncCycle
from joints.drivers.erob import CalibrationResult, ErobDriver
from joints.errors import (
    CommandError,
    ConfigError,
    DeviceFault,
    FrameError,
    PeerProtocolError,
    StateError,
)

__all__ = ["HEARTBEAT_MS", "MODES", "NODE_LOST", "CanopenAccess", "ErobCanopenDriver", "SyncCycle"]


@functools.lru_cache(maxsize=64)
def _entries(config: PdoConfig) -> tuple[tuple[int, int, int, bool], ...]:
    """:attr:`PdoConfig.entries`, computed once per configuration (a pure function of a frozen one)."""
    return config.entries

#: config ``mode`` -> CiA 402 mode of operation
MODES: Mapping[str, Mode] = {"pp": Mode.PP, "pv": Mode.PV, "pt": Mode.PT, "csp": Mode.CSP, "csv": Mode.CSV,
                             "cst": Mode.CST, "ip": Mode.IP}
HEARTBEAT_MS = 100  #: producer heartbeat time the driver sets (0x1017)
CONSUMER_FACTOR = 2.5  #: host consumer time = this x the producer time
LIFE_TIME_FACTOR = 4  #: 0x100D while the watchdog is armed (guard time = watchdog / 4)
STATE_TIMEOUT = 1.5  #: s for a CiA 402 state change (the brake releases in 0.5 s)
POLL = 0.005  #: s between two state reads while waiting
TEMPERATURE_PERIOD = 1.0  #: s between two SDO reads of 0x22A2 drive temperature by state()
_CANOPEN_FAULTS = {
    0x8130: ("life_guard_error", "the drive's life guarding expired: the host stopped guarding it (EMCY 0x8130)",
             "keep the host talking (the rig does while it waits), then clear_faults() and enable()"),
    0x8210: ("pdo_length_error", "an RPDO shorter than its mapping was dropped (EMCY 0x8210)",
             "check the RPDO mapping, then clear_faults()"),
    0x8250: ("rpdo_timeout", "an RPDO did not arrive within its deadline (EMCY 0x8250)",
             "send set-points every cycle, then clear_faults()"),
}
_CYCLIC_KIND = {Mode.CSP: "position", Mode.IP: "position", Mode.CSV: "velocity", Mode.CST: "torque"}


def _power_on_objects(node: int) -> dict[tuple[int, int], int]:
    """Object values after NMT reset communication (the parameters' defaults, COB-IDs + node)."""
    return {(o.index, o.subindex): EROB_PARAMS[n].default + (node if o.node_relative else 0)
            for n, o in EROB_CANOPEN.keys.items() if 0x1400 <= o.index < 0x1C00}


log = logging.getLogger("joints.drivers")


class ErobCanopenDriver(ErobDriver):
    """One eRob actuator on a CANopen bus (see the module docstring)."""

    start_check_names = ()

    def __init__(
        self,
        link: Any,
        node: int,
        *,
        profile: ErobProfile | str | None = None,
        clock: Clock | None = None,
        name: str = "",
        mode: str | Mode | None = None,
        sync_period: float = 0.001,
        heartbeat_ms: int = HEARTBEAT_MS,
        cycle: SyncCycle | None = None,
        eds: str | Path | None = None,
    ) -> None:
        self.link = link
        self.node = node
        cmap = EROB_CANOPEN if eds is None else map_from_eds(eds, EROB_CANOPEN)
        super().__init__(CanopenAccess(link, node, cmap), profile=profile, clock=clock or link.clock,
                         name=name or f"erob@canopen:{node}")
        if isinstance(mode, str):
            try:
                mode = MODES[mode]
            except KeyError:
                raise CommandError(f"{self.name}: mode {mode!r} is not one of {sorted(MODES)}") from None
        self.mode: Mode = mode or Mode.PP
        if not sync_period > 0:
            raise CommandError(f"{self.name}: sync_period must be > 0 s, got {sync_period!r}")
        self.sync_period = sync_period
        self.heartbeat_ms = heartbeat_ms
        self.group = cycle or SyncCycle(link, sync_period)
        self.group.drivers.append(self)
        self.tpdo1_cob = 0x180 + node
        self.tpdo2_cob = 0x280 + node
        self._up: Mode | None = None
        self._torque_limit_warned = False
        self._cw = 0
        self._target = 0
        self._pp_base = 0x000F | cia402.CW_CHANGE_SET_IMMEDIATELY  #: PP's controlword without bit 4
        self._rpdo = ERUNNER_RPDO1[self.mode]
        self._tpdos: tuple[PdoConfig, ...] = ERUNNER_TPDOS
        self._unpack: tuple[tuple[PdoConfig, ...], tuple[Callable[[bytes], tuple[int, ...]], ...]] | None = None
        self._pack: tuple[PdoConfig, Callable[[Sequence[int]], bytes], int] | None = None
        self._subs: list[Any] = []
        self.statusword = 0
        self.position = 0
        self.velocity = 0
        self.current = 0
        self.status_time = -math.inf
        self.status_cycle = 0
        self._prev_position: tuple[float, int] | None = None
        self.emcy: co.Emcy | None = None
        self.emcys: list[co.Emcy] = []
        self._watchdog_ms = 0
        self._last_guard = -math.inf
        self.temperature = math.nan  #: degC, 0x22A2 as last read (state(): at most every TEMPERATURE_PERIOD)
        self._temperature_time = -math.inf
        try:
            self._check_dictionary(cmap, eds)
        except ConfigError:
            self.group.drivers.remove(self)  # a shared cycle does not keep a driver that was refused
            raise

    def _check_dictionary(self, cmap: ParamMap[CanopenObject], eds: str | Path | None) -> None:
        """With an EDS (ZeroErr's, or a twin's export): every object this mode's PDOs and bring-up use
        is in the file with the data type the driver packs; else :class:`ConfigError` naming both."""
        if eds is None:
            return
        needed = [*(n for p in (self._rpdo, *ERUNNER_TPDOS, CYCLIC_TPDO1_CURRENT) for n in p.objects
                    if isinstance(n, str)), "statusword", "controlword", "modes_of_operation",
                  "modes_of_operation_display", "producer_heartbeat_time"]
        for name in dict.fromkeys(needed):
            ours = EROB_CANOPEN.key(name)
            theirs = cmap.keys.get(name)
            if theirs is None or theirs.datatype is not ours.datatype:
                found = "absent" if theirs is None else theirs.datatype.name
                raise ConfigError(f"{self.name}: {eds} has {ours} ({name}) {found}; mode {self.mode.name} packs it as "
                                  f"{ours.datatype.name}: use the EDS exported by `joints sim eds` or another mode",
                                  file=str(eds))

    def feedback_tpdo(self) -> PdoConfig:
        """The cyclic TPDO1: with the motor current if the cycle still fits the bus with it (every cyclic
        joint of the bus, :meth:`SyncCycle.fits`), else eRunner's statusword + position (E12)."""
        current = self.group.current
        if current is not None:
            return CYCLIC_TPDO1_CURRENT if current else ERUNNER_TPDOS[0]
        rpdo = max((ERUNNER_RPDO1[d.mode].size for d in self.group.drivers
                    if isinstance(d, ErobCanopenDriver) and d.mode.cyclic), default=6)
        return CYCLIC_TPDO1_CURRENT if self.group.fits(rpdo, CYCLIC_TPDO1_CURRENT.size) else ERUNNER_TPDOS[0]

    # -- bring-up ---------------------------------------------------------------------------
    @property
    def cyclic(self) -> bool:
        return self.mode.cyclic

    @property
    def answers_sync(self) -> bool:
        """OPERATIONAL in a cyclic mode: its TPDO1 answers every SYNC (the SYNC cycle counts them)."""
        return self._up is not None and self._up.cyclic

    @property
    def cycle_kind(self) -> str:
        """What :meth:`joints.rig.Rig.cycle` sends this joint: "position", "velocity" or "torque"."""
        kind = _CYCLIC_KIND.get(self.mode)
        if kind is None:
            raise CommandError(f"{self.name}: mode {self.mode.name} is not cyclic; configure mode = \"csp\", "
                               "\"csv\", \"cst\" or \"ip\" for Rig.cycle")
        return kind

    def _unsubscribe(self) -> None:
        for s in self._subs:
            s.cancel()
        self._subs.clear()

    def _subscribe(self) -> None:
        self._unsubscribe()
        link = self.link
        cobs = (self.tpdo1_cob, self.tpdo2_cob)
        self._subs.append(link.subscribe(lambda m: isinstance(m, co.Pdo) and m.cob_id in cobs and not m.remote,
                                         self.on_tpdo, only=cobs))
        self._subs.append(link.subscribe(lambda m: isinstance(m, co.Emcy) and m.node == self.node, self._on_emcy,
                                         only=(co.Emcy,)))

    def _pdo_writes(self, configs: Sequence[PdoConfig], known: dict[tuple[int, int], int]) -> None:
        for cfg in configs:
            kind = co.Kind[f"{cfg.kind}{cfg.number}"]
            comm = co.PdoComm(cfg.cob_id(self.node), cfg.transmission_type, cfg.inhibit_time, cfg.event_timer)
            for index, sub, value, size in co.pdo_configuration_writes(kind, comm, cfg.entries):
                if known.get((index, sub)) == value:
                    continue
                self.link.sdo_download(self.node, index, sub, value.to_bytes(size, "little"))
                known[(index, sub)] = value

    def bring_up(self, mode: Mode | None = None) -> None:
        """Configure the node for ``mode`` (chapter 5's sequence) and start it (NMT OPERATIONAL)."""
        mode = mode or self.mode
        link, node = self.link, self.node
        self._unsubscribe()
        self._up = None
        link.nmt(co.NmtCommand.STOP, node)
        link.nmt(co.NmtCommand.RESET_COMMUNICATION, node)
        link.wait_for(lambda m: isinstance(m, co.BootUp) and m.node == node, max(link.policy.timeout, 0.5))
        link.monitor(node).reset()
        self.write_param("modes_of_operation", int(mode))
        shown = self.read("modes_of_operation_display")
        if shown != int(mode):
            raise StateError(f"{self.name}: 0x6061 shows mode {shown} after 0x6060 = {int(mode)}")
        if mode.cyclic:
            self._set("cob_id_sync", 0x80, force=True)  # eRunner's "disable cob-id sync" (fig 5-18)
            self._set("communication_cycle_period", round(self.sync_period * 1e6), force=True)
        if mode is Mode.IP:
            ms = round(self.sync_period * 1e3)
            if 1 <= ms <= 255:
                self._set_many({"interpolation_time_period_value": ms, "interpolation_time_index": -3})
            else:
                self._set_many({"interpolation_time_period_value": round(self.sync_period * 1e4),
                                "interpolation_time_index": -4})
        self.mode = mode
        self._rpdo = ERUNNER_RPDO1[mode]
        self._tpdos = (self.feedback_tpdo(),) if mode.cyclic else ERUNNER_TPDOS
        known = _power_on_objects(node)
        self._pdo_writes((*self._tpdos, self._rpdo), known)
        self._subscribe()
        self._liveness()
        link.nmt(co.NmtCommand.START, node)
        self._up = mode
        self._cw = 0
        self.emcy = None

    def _liveness(self) -> None:
        """Heartbeat + host consumer, or life guarding while the watchdog is armed (never both: CiA 301)."""
        link, node = self.link, self.node
        if self._watchdog_ms:
            guard = max(1, self._watchdog_ms // LIFE_TIME_FACTOR)
            self.write_param("producer_heartbeat_time", 0)
            self._set_many({"guard_time": guard, "life_time_factor": LIFE_TIME_FACTOR})
            link.consume(node, 0.0)
            link.stop_guarding(node)
            self._last_guard = -math.inf
            self._keepalive()
        else:
            if self._cache.get("guard_time"):
                self._set_many({"guard_time": 0, "life_time_factor": 0})
            link.stop_guarding(node)
            self.write_param("producer_heartbeat_time", self.heartbeat_ms)
            link.consume(node, self.heartbeat_ms * 1e-3 * CONSUMER_FACTOR if self.heartbeat_ms else 0.0)

    def _ensure(self, mode: Mode | None = None) -> None:
        """The node is up in ``mode`` (default: the configured one); a change disables first."""
        want = mode or (self._up or self.mode)
        if self._up is want:
            return
        was = self._enabled and self._up is not None
        if was:
            self.disable()
        self.bring_up(want)
        if was:
            self.enable()

    # -- PDOs -------------------------------------------------------------------------------
    def _unpackers(self) -> tuple[Callable[[bytes], tuple[int, ...]], ...]:
        """The decoding of each configured TPDO, prepared once per configuration (``co.pdo_unpacker``)."""
        memo = self._unpack
        if memo is None or memo[0] is not self._tpdos:
            memo = self._unpack = (self._tpdos, tuple(co.pdo_unpacker(_entries(c)) for c in self._tpdos))
        return memo[1]

    def _send_rpdo(self, values: Sequence[int]) -> None:
        """RPDO1 with ``values``: its COB-ID and packing prepared once per configuration (``co.pdo_packer``: the
        bytes and errors of ``pack_pdo``)."""
        memo = self._pack
        if memo is None or memo[0] is not self._rpdo:
            memo = self._pack = (self._rpdo, co.pdo_packer(_entries(self._rpdo)), self._rpdo.cob_id(self.node))
        self.link.send_pdo(memo[2], memo[1](values))

    @property
    def sync_cobs(self) -> tuple[int, ...]:
        """The TPDOs the node sends on every SYNC (TPDO1 [+ TPDO2]): none before it is started or once lost."""
        if self._up is None:
            return ()
        m = self.link.monitors.get(self.node)
        if m is not None and m.lost is not None:
            return ()
        return (self.tpdo1_cob, self.tpdo2_cob)[:len(self._tpdos)]

    @property
    def sample_group(self) -> SyncCycle:
        """The bus's reads (:meth:`SyncCycle.read_states`): the joints of one bus are sampled by one SYNC."""
        return self.group

    def on_tpdo(self, msg: co.Pdo) -> None:
        self.group.paid(msg.cob_id)
        t = self.link.clock.now()
        if msg.cob_id == self.tpdo1_cob:
            try:
                sw, pos, *current = self._unpackers()[0](msg.data)
            except FrameError:
                return
            if current:
                self.current = current[0]
            if self._prev_position is not None and t > self._prev_position[0] and self.cyclic:
                self.velocity = round((pos - self._prev_position[1]) / (t - self._prev_position[0]))
            self._prev_position = (t, pos)
            self.statusword, self.position, self.status_time = sw, pos, t
            self.status_cycle = self.group.answered(self)
        elif len(self._tpdos) > 1:
            try:
                self.velocity, self.current = self._unpackers()[1](msg.data)
            except FrameError:
                return

    def _on_emcy(self, msg: co.Emcy) -> None:
        self.emcys.append(msg)
        del self.emcys[:-50]
        self.emcy = msg if msg.error_code else None

    def _control(self, cw: int, target: int | None = None) -> None:
        """RPDO1: controlword + the mode's target (applied at once, or at the next SYNC in cyclic modes)."""
        if target is not None:
            self._target = target
        self._cw = cw
        values = [cw, self._target] + [0] * (len(self._rpdo.objects) - 2)
        self._send_rpdo(values)
        if self.cyclic:
            self.link.sync()
            self.group.owe(self.clock.now())

    def _snapshot(self) -> float:
        """One SYNC and this node's TPDOs of it (statusword, position; velocity and current), TPDOs owed for an
        earlier SYNC waited out first (:meth:`SyncCycle.sample`); the clock time of the SYNC."""
        return self.group.sample((self,))

    def lost(self) -> str | None:
        """Why the node counts as lost (heartbeat consumer, node guarding), or None."""
        return self.link.lost(self.node)  # type: ignore[no-any-return]

    def _keepalive(self) -> None:
        if self._watchdog_ms:
            now = self.clock.now()
            period = max(1, self._watchdog_ms // LIFE_TIME_FACTOR) * 1e-3
            if now - self._last_guard >= period * 0.9:
                self._last_guard = now
                self.link.guard(self.node, max(self.link.policy.timeout, period))

    # -- state ------------------------------------------------------------------------------
    def _cia_state(self) -> State:
        return cia402.state_of(self.statusword)

    def state(self) -> RawState:
        """One SYNC and this node's TPDOs (guarding the node first while the watchdog is armed), stamped with
        the SYNC's time; the joints of one bus read together share one SYNC (:meth:`SyncCycle.read_states`)."""
        return self.group.read_states((self,))[self]

    def begin_read(self) -> bool:
        """Before the read's SYNC: the node up in its mode, guarded; whether it is sampled (not lost)."""
        self._ensure()
        self._keepalive()
        return self.lost() is None

    def end_read(self, at: float | None) -> RawState:
        """The state from the TPDOs of the SYNC sent at ``at`` (None: lost, not sampled), the temperature read by
        SDO when it is :data:`TEMPERATURE_PERIOD` old."""
        if at is None:
            return self._raw(self.clock.now())
        now = self.clock.now()
        if now - self._temperature_time >= TEMPERATURE_PERIOD:
            self._temperature_time = now
            self.temperature = float(self.read("part_of_power_temperature"))
        return self._raw(at)

    def observe(self) -> RawState:
        """The state by SDO reads only - no NMT, no bring-up, no PDO or mode change (for tools that only look).

        Works whatever mode and NMT state (PRE-OPERATIONAL or OPERATIONAL) the node is in; the
        host's own view (:attr:`statusword`, PDO values) is left untouched.
        """
        v = self.access.read_many(("statusword", "actual_position", "current_speed", "motor_current",
                                   "part_of_power_temperature"))
        sw = v["statusword"]
        try:
            st = cia402.state_of(sw)
        except Exception:  # noqa: BLE001 - a statusword that codes no state: reported as not enabled
            st = State.NOT_READY_TO_SWITCH_ON
        fault = 0
        if st in (State.FAULT, State.FAULT_REACTION_ACTIVE):
            fault = self.read("error_code") or 0xFF00
        enabled = st is State.OPERATION_ENABLED
        moving = enabled and (not cia402.target_reached(sw) or abs(v["current_speed"]) > 200)
        return RawState(position=v["actual_position"], velocity=v["current_speed"], current=v["motor_current"],
                        temperature=float(v["part_of_power_temperature"]), enabled=enabled, moving=moving,
                        fault=fault, time=self.clock.now(), extra={"statusword": sw, "node": self.node})

    def cycle_state(self) -> RawState:
        return self._raw(self.status_time)

    def _raw(self, t: float) -> RawState:
        sw = self.statusword
        lost = self.lost()
        try:
            st = self._cia_state()
        except Exception:  # noqa: BLE001 - a statusword that codes no state: reported as not enabled
            st = State.NOT_READY_TO_SWITCH_ON
        fault = 0
        if lost is not None:
            fault = NODE_LOST
        elif st in (State.FAULT, State.FAULT_REACTION_ACTIVE):
            fault = self.emcy.error_code if self.emcy is not None else self.read("error_code") or 0xFF00
        enabled = st is State.OPERATION_ENABLED and lost is None
        if not enabled and self._enabled and (fault or st in (State.SWITCH_ON_DISABLED, State.READY_TO_SWITCH_ON)):
            self._note_enable(False)
        reached = cia402.target_reached(sw)
        if self.mode is Mode.PP:
            moving = enabled and not reached
        else:
            moving = enabled and abs(self.velocity) > 200
        return RawState(position=self.position, velocity=self.velocity,
                        current=self.current if self.reports_current else math.nan,
                        temperature=self.temperature, enabled=enabled, moving=moving, fault=fault, time=t,
                        extra={"statusword": sw, "mode": int(self.mode), "node": self.node})

    @property
    def reports_current(self) -> bool:
        """Whether the TPDOs in use carry the motor current (0x6078)."""
        return any("motor_current" in p.objects for p in self._tpdos)

    def fault_text(self, code: int) -> str:
        f = self.fault(code)
        return f.text if f is not None else ""

    def fault(self, code: int) -> Fault | None:
        if not code:
            return None
        if code == NODE_LOST:
            return Fault(code, "node_lost", f"node {self.node} went silent (no heartbeat / node-guarding reply: power "
                         "loss, a cable, or the node reset)", "restore power and wiring, then clear_faults() and "
                         "enable() (the node is brought up again)", DEFINED_BY_JOINTS)
        if code in _CANOPEN_FAULTS:
            name, text, clears = _CANOPEN_FAULTS[code]
            return Fault(code, name, text, clears, "CiA 301 (EMCY)")
        return faults.fault(code)

    def check_fault(self) -> None:
        s = self.state()
        if s.fault:
            f = self.fault(s.fault)
            assert f is not None
            raise DeviceFault(self.name, s.fault, f.text, hint=f.clears, name=f.name)

    # -- power ------------------------------------------------------------------------------
    def _wait_state(self, want: State, timeout: float = STATE_TIMEOUT) -> None:
        deadline = self.clock.now() + timeout
        while True:
            self._snapshot()
            st = self._cia_state()
            if st is want:
                return
            if st is State.FAULT:
                code = self.emcy.error_code if self.emcy is not None else self.read("error_code")
                f = self.fault(code)
                raise DeviceFault(self.name, code, f.text if f else "fault", hint=f.clears if f else "",
                                  name=f.name if f else "drive_error")
            if self.clock.now() >= deadline:
                raise StateError(f"{self.name}: the drive did not reach {want.value} within {timeout} s "
                                 f"(it reports {st.value}, statusword 0x{self.statusword:04X})")
            self._pause()

    def _pause(self) -> None:
        """Wait a moment; the other nodes of the bus stay guarded meanwhile (their life guarding)."""
        for d in self.group.drivers:
            if isinstance(d, ErobCanopenDriver):
                d._keepalive()
        self.clock.sleep(POLL)

    pause = _pause  #: :class:`~joints.drivers.canopen_sync.SetpointNode`'s name for it

    def _hold_target(self) -> int:
        """The target that keeps the joint where it is in the present mode."""
        return self.position if self.mode in (Mode.PP, Mode.CSP, Mode.IP) else 0

    def enable(self) -> None:
        """CiA 402: shutdown, switch on, enable operation (RPDO1), each confirmed by the statusword."""
        self._ensure()
        self._snapshot()
        target = self._hold_target()
        for word in cia402.path(self._cia_state(), State.OPERATION_ENABLED):
            self._control(word, target)
            want = cia402.next_state(self._cia_state(), word)
            self._wait_state(want)
        self._control(cia402.COMMAND_WORD[cia402.Command.ENABLE_OPERATION] | self._mode_bits(), target)
        self._note_enable(True)
        if self.mode.cyclic:  # set-points act once the drive follows them (bit 12; IP: interpolation active)
            deadline = self.clock.now() + STATE_TIMEOUT
            while not self.statusword & cia402.SW_TARGET_FOLLOWED:
                if self.clock.now() >= deadline:
                    raise StateError(f"{self.name}: the drive does not follow the target after enable "
                                     f"(statusword 0x{self.statusword:04X})")
                self._pause()
                self._snapshot()

    def _mode_bits(self) -> int:
        if self.mode is Mode.PP:
            return cia402.CW_CHANGE_SET_IMMEDIATELY
        if self.mode is Mode.IP:
            return cia402.CW_ENABLE_IP
        return 0

    def _sdo_control(self, word: int, *, when: tuple[State, ...] | None = None) -> None:
        """A controlword by SDO, for a node this host has not brought up (another master may have
        left it running: it has no mapping of ours, and an SDO works in PRE-OPERATIONAL and
        OPERATIONAL alike); only ``when`` the drive reports one of those states (None: always)."""
        if when is not None:
            try:
                now = cia402.state_of(self.read("statusword"))
            except PeerProtocolError:  # a statusword that codes no state: nothing runs
                return
            if now not in when:
                return
        self.write_param("controlword", word, idempotent=False)

    def disable(self) -> None:
        """Shutdown (controlword 0x0006, fig 5-9): the drive is off, the brake holds. A node this
        host has not brought up gets it by SDO if it is switched on."""
        if self._up is None:
            self._sdo_control(cia402.COMMAND_WORD[cia402.Command.SHUTDOWN],
                              when=(State.SWITCHED_ON, State.OPERATION_ENABLED))
            self._note_enable(False)
            return
        self._control(cia402.COMMAND_WORD[cia402.Command.SHUTDOWN])
        self._note_enable(False)
        if self.lost() is None:
            self._snapshot()
            if self._cia_state() is State.OPERATION_ENABLED:
                self._wait_state(State.READY_TO_SWITCH_ON)

    # -- motion -----------------------------------------------------------------------------
    def _run(self, mode: Mode) -> None:
        self._ensure(mode)
        if not self._enabled:
            raise StateError(f"{self.name}: the motor is not enabled; call enable() first")

    def move_to(self, position: int, *, speed: int | None = None, acceleration: int | None = None,
                deceleration: int | None = None) -> None:
        """PP: profile (0x6081/0x6083/0x6084), target 0x607A + new set-point, acknowledge, clear bit 4; the joints
        of one bus moved together share the acknowledge's SYNC (:meth:`SyncCycle.move_together`)."""
        self.group.move_together({self: (position, speed, acceleration, deceleration)})

    def move_by(self, delta: int, *, speed: int | None = None, acceleration: int | None = None,
                deceleration: int | None = None) -> None:
        """PP relative (controlword bit 6)."""
        self._validate(target_relative_position=delta, profile_speed=speed, profile_acceleration=acceleration,
                       profile_deceleration=deceleration)
        self.group.setpoints({self: (delta, speed, acceleration, deceleration)}, relative=True)

    @property
    def setpoint_group(self) -> SyncCycle:
        """The bus's PP set-points (:meth:`SyncCycle.move_together`): acknowledged by one SYNC for all."""
        return self.group

    def check_move(self, target: int, speed: int | None, acc: int | None, dec: int | None) -> None:
        """A :meth:`move_to`'s values against the objects' ranges (:class:`CommandError`); nothing is sent."""
        self._validate(target_absolute_position=target, profile_speed=speed, profile_acceleration=acc,
                       profile_deceleration=dec)

    def start_setpoint(self, target: int, speed: int | None, acc: int | None, dec: int | None, *,
                       relative: bool) -> None:
        """PP (brought up and enabled first), the profile by SDO where it changed, then RPDO1: the target with
        controlword bit 4 (new set-point) rising - bit 4 is cleared first if it is still set."""
        self._run(Mode.PP)
        self._set_many(self._profile(speed, acc, dec))
        base = self._pp_base = 0x000F | cia402.CW_CHANGE_SET_IMMEDIATELY | (cia402.CW_RELATIVE if relative else 0)
        if self._cw & cia402.CW_NEW_SETPOINT:
            self._control(base, target)
        self._control(base | cia402.CW_NEW_SETPOINT, target)

    def setpoint_acknowledged(self, since: float) -> bool:
        """Whether the last TPDO1's statusword acknowledges the set-point (bit 12); :class:`StateError` if it
        shows a fault or :data:`STATE_TIMEOUT` has passed since ``since`` (clock time) without it."""
        sw = self.statusword
        if cia402.setpoint_acknowledged(sw):
            return True
        if cia402.is_fault(sw) or self.clock.now() >= since + STATE_TIMEOUT:
            raise StateError(f"{self.name}: the drive did not acknowledge the set-point (statusword 0x{sw:04X})")
        return False

    def end_setpoint(self) -> None:
        """RPDO1 with controlword bit 4 cleared (the set-point handshake's end), the target kept."""
        self._control(self._pp_base, self._target)

    def move_continuous(self, speed: int, *, acceleration: int | None = None, deceleration: int | None = None) -> None:
        raise CommandError(f"{self.name}: CiA 402 has no continuous position move; use set_velocity (PV)")

    def move_repetitive(self, position: int, *, speed: int | None = None, acceleration: int | None = None,
                        deceleration: int | None = None, dwell: int | None = None) -> None:
        raise CommandError(f"{self.name}: CiA 402 has no repetitive move; send the moves with move_to")

    def stop_repetitive(self) -> None:
        raise CommandError(f"{self.name}: CiA 402 has no repetitive move; use stop()")

    def set_velocity(self, velocity: int, *, acceleration: int | None = None, deceleration: int | None = None) -> None:
        """PV: ramps 0x6083/0x6084, target velocity 0x60FF (RPDO1)."""
        self._validate(target_speed=velocity, profile_acceleration=acceleration, profile_deceleration=deceleration)
        self._run(Mode.PV)
        self._set_many(self._profile(None, acceleration, deceleration))
        self._control(0x000F, velocity)

    def _per_mille(self, current_ma: int) -> int:
        torque = current_ma * 1e-3 * self.profile.torque_constant
        return max(-32768, min(32767, round(torque / self.profile.rated_torque * 1000)))

    def set_current(self, current: int) -> None:
        """PT: target torque 0x6071 (per mille of rated torque, from the current through the torque constant)."""
        self._validate(target_current=current)
        self._run(Mode.PT)
        self._control(0x000F, self._per_mille(current))

    def stop(self) -> None:
        """Halt (bit 8) in the position modes; target 0 in the velocity and torque modes. A node
        this host has not brought up is halted by SDO (controlword 0x010F) if it is enabled."""
        if self._up is None:
            self._sdo_control(cia402.COMMAND_WORD[cia402.Command.ENABLE_OPERATION] | cia402.CW_HALT,
                              when=(State.OPERATION_ENABLED,))
            return
        if not self._enabled or self.lost() is not None:
            return
        if self.mode in (Mode.PP, Mode.IP, Mode.CSP):
            self._control((self._cw | cia402.CW_HALT) & ~cia402.CW_NEW_SETPOINT)
        else:
            self._control(0x000F, 0)

    def emergency_stop(self) -> None:
        """Quick stop (controlword 0x0002): the quick-stop ramp, then SWITCH ON DISABLED (0x605A = 2).
        A node this host has not brought up gets it by SDO (it never enables a drive, whatever its state)."""
        if self._up is None:
            self._sdo_control(cia402.COMMAND_WORD[cia402.Command.QUICK_STOP])
            self._note_enable(False)
            return
        self._control(cia402.COMMAND_WORD[cia402.Command.QUICK_STOP])
        self._note_enable(False)

    def clear_errors(self) -> None:
        """Fault reset (rising controlword bit 7); a lost node is brought up again. A node this host
        has not brought up gets the reset by SDO (its NMT state and mapping left alone)."""
        if self._up is None and self.lost() is None:
            for word in (0x0000, cia402.COMMAND_WORD[cia402.Command.FAULT_RESET], 0x0000):
                self._sdo_control(word)
            self.emcy = None
            return
        if self.lost() is not None or self._up is None:
            self.link.monitor(self.node).reset()
            self.bring_up(self._up or self.mode)
        self._control(0x0000)
        self._control(cia402.COMMAND_WORD[cia402.Command.FAULT_RESET])
        self._control(0x0000)
        self.emcy = None

    def forget(self) -> None:
        """Also the times kept on the clock (a sim reset restarts it): the temperature is read at the next
        state(), the guarding and the cyclic velocity start again."""
        super().forget()
        self._up = None
        self._cw = 0
        self.emcy = None
        self.temperature = math.nan
        self._temperature_time = -math.inf
        self._last_guard = -math.inf
        self.status_time = -math.inf
        self._prev_position = None
        self.link.monitor(self.node).reset()
        self.link.consume(self.node, 0.0)

    # -- cyclic (Rig.cycle through SyncCycle) ---------------------------------------------------
    def cycle_send(self, target: int) -> None:
        """This cycle's set-point (device units of :attr:`cycle_kind`): RPDO1, applied at the SYNC."""
        if self._up is None or not self.cyclic:
            raise StateError(f"{self.name}: not in a cyclic mode (mode {self.mode.name}); enable() it first")
        self._keepalive()
        value = self._per_mille(target) if self.mode is Mode.CST else target
        self._target = value
        self._cw = (self._cw | 0x000F) & ~cia402.CW_HALT if self._enabled else self._cw
        values = [self._cw, value] + [0] * (len(self._rpdo.objects) - 2)
        self._send_rpdo(values)

    # -- host-side contracts ----------------------------------------------------------------
    def set_communication_timeout(self, milliseconds: int) -> None:
        """Life guarding: guard time = ``milliseconds`` / 4, life time factor 4 (0 = heartbeat again)."""
        self._watchdog_ms = int(milliseconds)
        if self._up is None or self.lost() is not None:
            return  # applied at the next bring-up (a lost node cannot take it now)
        self._liveness()

    def communication_timeout(self) -> int:
        return self._watchdog_ms

    def apply_limits(self, *, position: tuple[int, int] | None = None, velocity: int | None = None,
                     current: int | None = None) -> None:
        """0x607D software position limits, 0x6080 max motor speed (volatile). A current (torque) limit has
        no object to go to (ZeroErr's EDS has no 0x6072/0x6073): it stays a host-side limit only (every
        torque command is still checked against it before it is sent), and a warning says so once."""
        if current is not None and not self._torque_limit_warned:
            self._torque_limit_warned = True
            log.warning("%s: limits.torque is enforced by the host only: over CANopen the eRob has no max torque "
                        "or max current object (ZeroErr's EDS lacks 0x6072/0x6073), so the drive itself does not "
                        "limit its current; set max_motor_current over Modbus RTU or the CAN custom protocol if "
                        "the drive must enforce it", self.name)
        self._ensure()
        if position is not None:
            self._set_many({"min_position_limit_value": position[0], "max_position_limit_value": position[1]})
        if velocity is not None:
            self._set("max_speed", max(1, min(velocity, 0x7FFFFFFF)))

    def motion_targets(self) -> dict[str, tuple[str, float]]:
        rad = self.units.position
        per_mille = self.profile.rated_torque / 1000.0 / self.profile.torque_constant  # A per unit
        return {"target_absolute_position": ("position", rad), "interpolation_data_record_1": ("position", rad),
                "profile_speed": ("velocity", rad), "target_speed": ("velocity", rad),
                "target_torque": ("current", per_mille)}

    def identity(self) -> dict[str, object]:
        """0x1018 identity and 0x1000 device type (and the supported modes 0x6502)."""
        out: dict[str, object] = {}
        for key in ("device_type", "vendor_id", "product_code", "revision_number"):
            out[key] = f"0x{self.read(key):08X}"
        bits = self.read("supported_drive_modes")
        out["modes"] = sorted(m.name.lower() for m in cia402.modes_from_bits(bits))
        return out

    def calibrate_zero(self, *, multi_turn: bool = False, save: bool = True,
                       confirm: bool = False) -> CalibrationResult:
        raise CommandError(f"{self.name}: zero calibration needs the position offset, which the CANopen map does "
                           "not reach; use Modbus RTU; nothing was sent")

    def save_parameters(self, *, confirm: bool = False) -> None:
        raise CommandError(f"{self.name}: ZeroErr's EDS lists 0x1010 store parameters, but what an eRob saves "
                           "through it is not documented (the twin only stores the value); save over Modbus RTU or "
                           "the CAN custom protocol; nothing was sent")
