"""The eRob's firmware: the drive's own behaviour, by parameter name, without a protocol.

Rule: the firmware IS the drive. It holds the eRob's parameters
(:data:`~joints.devices.erob.params.EROB_PARAMS`, the names of the Modbus manual's registers), acts
on writes as the manual says the drive does, runs the drive state machine of
:mod:`joints.devices.erob.state`, and every physics substep closes its own loops - profile
generator (:mod:`joints.devices.motion`) -> position loop (``position_loop_gain``) -> speed loop
(``speed_loop_gain`` / ``speed_loop_integral``) -> current limits -> torque = current x torque
constant. It returns a torque for the joint; it never sets a position. Status values
(``actual_position``, ``motion_status`` ...) are computed when a front reads them. Protocol
fronts reach it by name (:class:`~joints.sim.firmware.Firmware`); the Modbus front
(:mod:`joints.sim.modbus_front`) serves it over the register table
:data:`~joints.devices.erob.registers.EROB_MODBUS` at the address ``modbus_address`` held at
power-on. No wall clock: time advances only through :meth:`ErobFirmware.step`.

Conventions the manuals leave open (documented firmware choices):

* Gains: ``position_loop_gain`` is Kp in 0.1 /s (speed command = Kp x position error);
  ``speed_loop_gain`` is the speed-loop bandwidth in rad/s (torque = J x bandwidth x speed
  error, J = the joint's inertia seen by the drive); ``speed_loop_integral`` is the integral time
  constant in 0.1 ms. The speed loop adds the profile's acceleration as feedforward
  (current = J x a_ref / kt), so the integral does not have to carry the ramps.
* Torque-mode max speed (0x00D8) = 0 means "no limit but max_speed" (the manual's 5.3.2 sets 0 and
  the motor still turns, ERRATA DOC-EROB-EN-6). Writing it while enabled is refused (Modbus
  exception 03).
* Min/max position limit with min >= max means "no software limits".
* Fault codes not in our manuals use the CiA 402 error codes (following error 0x8611, speed error
  0x8400, stall 0x7121, software position limit 0x8612, over-temperature 0x4310); the RS485
  watchdog is the manual's 0xFA2; start while the motor is off is the eRunner code 0x0027.
* "Enable" releases the brake and the motor is ready 500 ms later (the manual's wait); a start,
  speed or current command before that is refused with 0x0027 and nothing moves (the state
  machine of :mod:`joints.devices.erob.state`).
* The settle timer of ``status_of_achieving_position`` (``time_setting_of_achieving_position``)
  runs in the drive's slow task and when that status is read; reading other parameters does not
  touch it.
* Continuous motion (motion mode 0) ramps with the acceleration whenever the profile speed is
  faster than the present speed, a reversal included (speed mode decelerates to the reversal).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

from joints.devices.erob import faults
from joints.devices.erob.params import EROB_PARAMS
from joints.devices.erob.profiles import ErobProfile
from joints.devices.erob.registers import (
    COUNTS_PER_REV,
    AchieveStatus,
    MotionMode,
    MotionStatus,
    OperationMode,
)
from joints.devices.erob.state import ENABLE_DELAY, ENABLED, Event
from joints.devices.erob.state import step as transition
from joints.errors import ParameterRefused, Refusal
from joints.sim import erob_kernel as K
from joints.sim.erob_kernel import (
    COUNTS_PER_RAD,
    FOLLOWING_ERROR,
    OVER_TEMPERATURE,
    POSITION_LIMIT,
    SPEED_ERROR,
    STALL,
    SUPERVISION_PERIOD,
)
from joints.sim.firmware import Firmware
from joints.sim.sensors import Sensor, model_of

__all__ = [
    "COUNTS_PER_RAD",
    "EMULATOR_FAULTS",
    "ENABLE_DELAY",
    "FOLLOWING_ERROR",
    "OVER_TEMPERATURE",
    "POSITION_LIMIT",
    "SPEED_ERROR",
    "STALL",
    "ErobFirmware",
    "fault_text",
    "power_on_defaults",
]

ESTOP_TIME = 0.04  #: s, emergency stop decelerates within this (manual: < 50 ms)
#: parameters whose values _cache_settings() turns into loop constants (a write to any other
#: parameter, e.g. a target, does not need the recomputation)
_CACHED_SETTINGS = frozenset((
    "position_offset", "position_loop_gain", "speed_loop_gain", "speed_loop_integral",
    "continuous_current", "peak_current", "max_motor_current", "peak_current_time", "max_speed",
    "max_acceleration", "profile_acceleration", "profile_deceleration", "profile_speed",
    "modbus_communication_timeout_duration", "max_position_error", "max_speed_error",
))
_TORQUE = int(OperationMode.TORQUE)
_SPEED = int(OperationMode.SPEED)
__all__ += ["SUPERVISION_PERIOD"]

EMULATOR_FAULTS = {
    FOLLOWING_ERROR: "position following error above max_position_error (0x00B9)",
    SPEED_ERROR: "speed error above max_speed_error (0x00BB)",
    STALL: "motor stalled (struck current/speed/time, 0x00C5-0x00C9)",
    POSITION_LIMIT: "position outside min/max position limit (0x00BD/0x00BF)",
    OVER_TEMPERATURE: "power stage above power_temperature_protection_value (0x00D1)",
}


def fault_text(code: int) -> str:
    """Text of a fault the twin can raise (manual codes first, then the CiA 402 ones)."""
    if code in faults.FAULTS:
        return faults.FAULTS[code].text
    return EMULATOR_FAULTS.get(code, faults.describe(code).text)


def power_on_defaults(profile: ErobProfile, address: int) -> dict[str, int]:
    """Parameter values after power-on of a factory-fresh drive of this variant."""
    max_speed = round(profile.max_speed * COUNTS_PER_RAD)
    cont = round(profile.rated_current * 1000)
    peak = round(max(profile.peak_current, profile.rated_current) * 1000)
    return {
        "modbus_address": address,
        "modbus_baud_rate": 4,
        "modbus_communication_timeout_duration": 0,
        "position_loop_gain": 500,  # Kp = 50 /s
        "speed_loop_gain": 200,  # bandwidth 200 rad/s
        "speed_loop_integral": 200,  # Ti = 20 ms
        "operation_mode": int(OperationMode.POSITION),
        "motion_mode": int(MotionMode.ABSOLUTE),
        "control_source": 0,
        "profile_speed": max_speed // 4,
        "profile_acceleration": max_speed,
        "profile_deceleration": max_speed,
        "dwell_time": 20000,  # 1 s
        "position_reaches_set_precision": 100,
        "time_setting_of_achieving_position": 200,  # 10 ms
        "continuous_current": cont,
        "peak_current": peak,
        "peak_current_time": 1000,
        "max_speed": max_speed,
        "max_acceleration": 10 * max_speed,
        "max_position_error": 10484,
        "max_speed_error": 84000,
        "min_position_limit_value": 0,
        "max_position_limit_value": 0,
        "max_phase_current": round(peak * 1.2),
        "max_motor_current": round(peak * 1.1),
        "struck_current": round(cont * 1.2),
        "struck_speed": 500,
        "struck_time": 20000,  # 1 s
        "min_permissible_bus_voltage": 44000,
        "max_permissible_bus_voltage": 55000,
        "power_temperature_protection_value": 85,
        "torque_control_mode_max_speed": 0,
        "bus_voltage": 48000,
        "part_of_power_temperature": 30,
        "status_of_achieving_position": int(AchieveStatus.MOTOR_OFF),
    }


#: Parameters kept over a power cycle when saved: the R/W settings (not status or commands), those
#: only the CAN custom protocol reaches (node id, jerk, ...) included.
_SETTINGS = tuple(p.name for p in EROB_PARAMS if p.access.value == "R/W")
ARRIVAL_WINDOW = K.ARRIVAL_WINDOW
_STATUS_INDEX = {name: i for i, name in enumerate(K.STATUS_NAMES)}
_STATUS_COUNT = len(K.STATUS_NAMES)
#: where the status values the sensors report are (:meth:`_StatusRead.finish`)
_SENSED_COUNTS, _SENSED_SPEED, _SENSED_CURRENT = (_STATUS_INDEX[n]
                                                  for n in ("actual_position", "current_speed", "motor_current"))
_REPETITIVE = int(MotionMode.REPETITIVE)


class _Generator:
    """The profile generator's columns by their short names: ``fw.gen.active`` is ``fw.gen_active`` (declared in
    :class:`joints.sim.erob_kernel.Columns`)."""

    __slots__ = ("_fw",)

    def __init__(self, fw: ErobFirmware) -> None:
        self._fw = fw

    @property
    def active(self) -> bool:
        return self._fw.gen_active

    @property
    def target(self) -> float:
        return self._fw.gen_target

    @property
    def continuous(self) -> bool:
        return self._fw.gen_continuous

    @property
    def stopping(self) -> bool:
        return self._fw.gen_stopping

    @property
    def rate(self) -> float:
        return self._fw.gen_rate


class ErobFirmware(Firmware, K.Columns):
    """One eRob's firmware, coupled to one simulated joint.

    ``address`` is the power-on value of ``modbus_address``; ``inertia`` the J the drive's gains
    are tuned for (default: the profile's rotor inertia at the output). The per-substep loops
    are :func:`joints.sim.erob_kernel.step` on the firmware's row (:attr:`KERNEL` rows of
    :data:`~joints.sim.erob_kernel.WIDTH` floats), which a world adopts into its table.
    """

    #: the kernel rows this twin steps (see :mod:`joints.sim.stepping`)
    KERNEL = K.KIND

    #: motion commands: the drive acts on them ``command_delay`` (the profile's) after they arrive
    DELAYED = frozenset((
        "target_current", "target_speed", "start_operating", "stop_operating", "emergency_stop",
        "stop_repetitive_motion",
    ))

    def __init__(
        self,
        profile: ErobProfile,
        address: int = 1,
        *,
        inertia: float | None = None,
        multi_turn: bool = True,
        ambient: float = 30.0,
        quirks: frozenset[str] = frozenset(),
    ) -> None:
        super().__init__(EROB_PARAMS, values=power_on_defaults(profile, address))
        self.quirks = quirks  #: the firmware profile's quirks (joints.devices.quirks), read by the fronts
        self._bind_row([0.0] * K.WIDTH)
        self.profile = profile
        self.multi_turn = multi_turn
        self.ambient = ambient
        self.inertia = inertia if inertia is not None else profile.armature  #: J the drive tunes for
        self.kt = profile.torque_constant
        self.command_delay = profile.command_delay
        self.gen = _Generator(self)
        #: the drive's sensors (joints.sim.sensors): what a read of position, speed and current reports
        self.sensor = Sensor(model_of(profile), f"erob:{address}", COUNTS_PER_RAD)
        self.sensors = (self.sensor,)
        self.computed.update({
            "actual_position": self._sensed_counts,
            "given_position": lambda: round(self._get(K.P_REF)) + self.offset,
            "position_error": lambda: round(self._get(K.P_REF) - self._get(K.POS)),
            "given_speed": lambda: round(self._get(K.V_CMD) if K.is_enabled(self._get(K.STATE)) else 0.0),
            "current_speed": self._sensed_speed,
            "speed_error": lambda: round((self._get(K.V_CMD) - self._get(K.VEL))
                                         if K.is_enabled(self._get(K.STATE)) else 0.0),
            "given_current": lambda: round(self._get(K.I_CMD)),
            "motor_current": self._sensed_current,
            "part_of_power_temperature": lambda: round(self._get(K.TEMPERATURE)),
            "torque_sensor_value": lambda: round(self._get(K.I_OUT) * self.kt),
            "error_code": lambda: int(self._get(K.FAULT_CODE)),
            "motion_status": self._motion_status,
            "status_of_achieving_position": lambda: self._k.achieve(self._row, self._k.moving(self._row)),
        })
        #: the status functions as made here (the one-call status read stands in for these only)
        self._own_computed = dict(self.computed)
        self._commands = {
            "enable_the_motor": self._enable_command,
            "start_operating": self._start,
            "stop_operating": lambda value: self._stop(self.values["profile_deceleration"]),
            "emergency_stop": self._emergency_stop,
            "stop_repetitive_motion": self._stop_repetitive,
            "clear_errors": self._clear_errors,
            "save_parameters": lambda value: self.save(_SETTINGS),
            "release_brake": self._release_brake,
            "reset_output_encoder": self._reset_output_encoder,
        }
        self._reset_state()

    # -- the row --------------------------------------------------------------------------------
    def _bind_row(self, row: Any) -> None:
        #: the working state (a row of the world's table once a world adopted it)
        self._row: Any = row
        if isinstance(row, list):
            self._get: Callable[[int], float] = row.__getitem__  #: column -> float
            self._k: Any = K.PY_OPS  #: the kernel helpers as Python
        else:  # a numpy row: Python floats out, the helpers compiled
            self._get = row.item
            self._k = K.compiled_ops()

    def kernel_rows(self) -> list[list[float]]:
        """The twin's rows as they stand (one: the drive)."""
        return [[float(x) for x in self._row]]

    def adopt(self, table: Any, first: int) -> None:
        """Run on row ``first`` of ``table`` from now on (its present state copied there)."""
        values = self.kernel_rows()[0]
        row = table[first]
        for k, x in enumerate(values):
            row[k] = x
        self._bind_row(row)

    def kernel_row(self, channel: str | None) -> int:
        """Which of the twin's rows steps ``channel``'s joint."""
        return 0

    # the row's columns are attributes of the twin: declared once, in :class:`joints.sim.erob_kernel.Columns`

    # -- power-on state ---------------------------------------------------------------------
    def _reset_state(self) -> None:
        s = self._row
        kt, ambient = float(self.kt), float(self.ambient)  # the drive's constants (columns too) stay
        for k in range(K.WIDTH):
            s[k] = 0.0
        s[K.STATE] = K.MOTOR_OFF
        s[K.ENABLED_AT] = -1.0
        self._k.gen_clear(s)
        s[K.REPEAT_LEG_TO_TARGET] = 1.0
        s[K.DWELL_UNTIL] = -1.0
        s[K.IN_WINDOW_SINCE] = -1.0
        s[K.PEAK_SINCE] = -1.0
        s[K.STALL_SINCE] = -1.0
        s[K.TEMPERATURE] = ambient
        s[K.BRAKE_HOLD] = math.nan
        s[K.LAST_FRAME] = -1.0
        s[K.KT] = kt
        s[K.RATED_CURRENT] = float(self.profile.rated_current)
        s[K.AMBIENT] = ambient
        self._cache_settings()

    def power_cycle(self) -> None:
        """Simulated power off/on: saved settings survive, everything else is power-on default."""
        pos = self.pos
        super().power_cycle()
        self._reset_state()
        self.sensor.reseed()  # the sensors' noise restarts with the drive: a world reset is reproducible
        # absolute encoder: a single-turn module keeps only the angle within one turn
        s = self._row
        s[K.POS] = pos if self.multi_turn else pos % COUNTS_PER_REV
        s[K.P_REF] = s[K.POS]

    @property
    def enabled(self) -> bool:
        """The motor is enabled (brake released or releasing)."""
        return K.is_enabled(self._get(K.STATE))

    # -- settings -----------------------------------------------------------------------------
    def _cache_settings(self) -> None:
        g = self.values
        s = self._row
        s[K.MODE] = float(g["operation_mode"])
        s[K.WATCHDOG] = g["modbus_communication_timeout_duration"] * 1e-3  # s, 0 = off
        s[K.MAX_POSITION_ERROR] = float(g["max_position_error"])
        s[K.MAX_SPEED_ERROR] = float(g["max_speed_error"])
        s[K.OFFSET] = float(g["position_offset"])
        s[K.KP] = g["position_loop_gain"] / 10.0
        bw = float(g["speed_loop_gain"])
        ti = g["speed_loop_integral"] * 1e-4
        # torque per (count/s) of speed error -> current per (count/s) in mA
        kv = self.inertia * bw / COUNTS_PER_RAD / self.kt * 1000.0
        s[K.KV] = kv
        s[K.KI] = kv / ti if ti > 0 else 0.0
        s[K.KFF] = self.inertia / COUNTS_PER_RAD / self.kt * 1000.0  # mA per count/s^2
        s[K.I_CONT] = float(g["continuous_current"])
        i_peak = float(max(g["peak_current"], 1))
        i_max = float(max(g["max_motor_current"], 1))
        s[K.I_PEAK] = i_peak
        s[K.I_MAX] = i_max
        s[K.PEAK_TIME] = g["peak_current_time"] * 1e-3
        s[K.I_LIM] = min(i_peak, i_max)
        # holding brake: ~100 Hz stiffness against the drive's own inertia, damping ratio 0.7,
        # slipping above twice the rated torque
        brake_k = self.inertia * 400.0**2 / 4
        s[K.BRAKE_K] = brake_k
        s[K.BRAKE_C] = 2.0 * 0.7 * math.sqrt(brake_k * self.inertia)
        s[K.BRAKE_HOLD_TORQUE] = 2.0 * self.profile.rated_torque
        vmax = float(max(g["max_speed"], 1))
        amax = float(max(g["max_acceleration"], 1))
        s[K.VMAX] = vmax
        s[K.AMAX] = amax
        # profile parameters as floats for the per-substep loops (refreshed on every settings write)
        s[K.ACC] = float(g["profile_acceleration"]) or amax
        s[K.DEC] = float(g["profile_deceleration"]) or amax
        speed = float(g["profile_speed"])
        s[K.SPEED] = speed
        s[K.VPROF] = min(abs(speed), vmax)
        for name, k in K.PARAMS.items():
            s[k] = float(g[name])

    def set(self, name: str, value: int) -> None:
        super().set(name, value)
        k = K.PARAMS.get(name)
        if k is not None:
            self._row[k] = float(self.values[name])
        elif name in _CACHED_SETTINGS or name == "operation_mode":
            self._cache_settings()

    def gain_params(self, channel: str | None = None) -> dict[str, str]:
        """The loop-gain parameters (for domain randomisation: joints.sim.world.World.perturb)."""
        return {"position": "position_loop_gain", "speed": "speed_loop_gain", "integral": "speed_loop_integral"}

    def place(self, q: float) -> None:
        """The joint is at ``q`` [rad] and at rest (start state, reset): encoder, setpoint and brake follow."""
        s = self._row
        s[K.POS] = s[K.P_REF] = q * COUNTS_PER_RAD
        s[K.VEL] = s[K.V_REF] = 0.0
        s[K.BRAKE_HOLD] = s[K.POS]

    def reader(self, names: Sequence[str]) -> Callable[[], list[int]]:
        """A prepared read (:meth:`Firmware.reader`); a block with the status values computes them
        all in one kernel call (:func:`joints.sim.erob_kernel.status`, the same values)."""
        generic = super().reader(names)
        names = tuple(names)
        index = _STATUS_INDEX
        own = self._own_computed
        if "status_of_achieving_position" not in names or any(
                n in self.computed and (n not in index or self.computed[n] is not own.get(n)) for n in names):
            return generic  # other computed values, or ones replaced since (tests count calls)
        types = self._type_range
        entries = tuple((index.get(n, -1), n, *types[n]) for n in names)
        return _StatusRead(self, names, entries)

    def fused_exchange(self, world: Any, bus: Any, front: Any, line: Any) -> Any:
        """The one-call exchange of this twin's steady Modbus requests (:mod:`joints.sim.erob_exchange`), or None."""
        from joints.sim.erob_exchange import prepare

        return prepare(world, bus, front, line)

    def counts(self) -> int:
        """Actual position value: encoder counts + position offset."""
        return round(self._get(K.POS)) + self.offset

    def _sensed_counts(self, get: Callable[[int], float] | None = None) -> int:
        """``actual_position`` as the drive reports it (:mod:`joints.sim.sensors`); ``get``: the row's columns as
        they stood when it was read (default: the row now)."""
        sensor = self.sensor
        if sensor.ideal:
            return self.counts()
        get = self._get if get is None else get
        pos = sensor.position(get(K.TIME), get(K.POS) / COUNTS_PER_RAD, get(K.VEL) / COUNTS_PER_RAD)
        return round(pos * COUNTS_PER_RAD) + self.offset

    def _sensed_speed(self, get: Callable[[int], float] | None = None) -> int:
        """``current_speed`` [count/s]: the drive's velocity estimate."""
        get = self._get if get is None else get
        sensor = self.sensor
        if sensor.ideal:
            return round(get(K.VEL))
        return round(sensor.velocity(get(K.POS) / COUNTS_PER_RAD, get(K.VEL) / COUNTS_PER_RAD) * COUNTS_PER_RAD)

    def _sensed_current(self, get: Callable[[int], float] | None = None) -> int:
        """``motor_current`` [mA] as the drive measures it."""
        i = (self._get if get is None else get)(K.I_OUT)
        sensor = self.sensor
        if sensor.ideal:
            return round(i)
        return round(sensor.current(i * 1e-3) * 1e3)

    def _sensed(self, get: Callable[[int], float]) -> tuple[int, int, int]:
        """``(_sensed_counts(get), _sensed_speed(get), _sensed_current(get))`` of a sensor that is not ideal, in one
        call of it (:meth:`~joints.sim.sensors.Sensor.sense`: the same draws in the same order, the same bits)."""
        return self._sensed_at(get(K.TIME), get(K.POS), get(K.VEL), get(K.I_OUT))

    def _sensed_at(self, t: float, pos: float, vel: float, i: float) -> tuple[int, int, int]:
        """:meth:`_sensed` of the row's time, position, velocity and current (its columns' values)."""
        p, v, c = self.sensor.sense(t, pos / COUNTS_PER_RAD, vel / COUNTS_PER_RAD, i * 1e-3)
        return round(p * COUNTS_PER_RAD) + self.offset, round(v * COUNTS_PER_RAD), round(c * 1e3)

    # -- what the fronts call ---------------------------------------------------------------
    def frame_received(self) -> None:
        K.frame(self._row)  # a jitable helper, as Python here (two row accesses)

    def check_write(self, name: str, value: int) -> None:
        if name == "torque_control_mode_max_speed" and self.enabled:
            raise ParameterRefused(Refusal.STATE, name, "torque-mode max speed only while disabled")

    def on_write(self, name: str, value: int) -> None:
        k = K.PARAMS.get(name)
        if k is not None:
            self._row[k] = float(value)
        command = self._commands.get(name)
        if command is not None:
            command(value)
        elif name in _CACHED_SETTINGS:
            self._cache_settings()
        elif name == "target_speed":
            self._speed_command(value)  # acts in speed mode only
        elif name == "target_current":
            self._k.target_current(self._row, float(value))  # the row's target was set above; a motion command
        elif name == "operation_mode":
            self._row[K.MODE] = float(value)
            self._change_mode()

    # -- state machine ----------------------------------------------------------------------
    def _ready_or_refuse(self) -> bool:
        return bool(self._k.ready_or_refuse(self._row))

    def _raise_fault(self, code: int) -> None:
        self._k.raise_fault(self._row, float(code))

    def _enable_command(self, value: int) -> None:
        if value:
            self._enable()
        else:
            self.state = transition(self.state, Event.DISABLE) or self.state
            self._k.motor_off(self._row)

    def _enable(self) -> None:
        state = self.state
        new = transition(state, Event.ENABLE)
        if new is None:
            return  # a faulted drive does not enable until errors are cleared
        self.state = new
        if state not in ENABLED:
            s = self._row
            s[K.ENABLED_AT] = s[K.TIME]
            s[K.P_REF] = s[K.POS]
            s[K.V_REF] = 0.0
            s[K.INTEG] = 0.0
            self._k.gen_clear(s)
            s[K.BRAKE_HOLD] = math.nan
            s[K.BRAKE_RELEASED] = 0.0

    def ready(self) -> bool:
        """The motor is on and its brake released: motion commands act now (for protocol fronts)."""
        return bool(self._k.ready(self._row))

    def trip(self, code: int) -> None:
        """A protection a protocol front supervises (CANopen life guarding) trips with ``code``."""
        self._raise_fault(code)

    def _release_brake(self, value: int) -> None:
        """Release the holding brake of a motor that is off (CAN 0x014F): the joint moves freely until
        the next enable or disable hands the brake back to the drive."""
        if not self.enabled:
            self._row[K.BRAKE_RELEASED] = 1.0

    def _clear_errors(self, value: int) -> None:
        if value:
            self.fault = 0
            self.state = transition(self.state, Event.CLEAR) or self.state

    # -- commands ---------------------------------------------------------------------------
    def _change_mode(self) -> None:
        s = self._row
        self._k.gen_clear(s)
        s[K.INTEG] = 0.0
        s[K.P_REF] = s[K.POS]
        s[K.V_REF] = s[K.VEL] if K.is_enabled(s[K.STATE]) else 0.0
        s[K.MODE_SPEED_TARGET] = 0.0
        s[K.STARTED] = 0.0

    def _clamp_target(self, target: float) -> float:
        return float(self._k.clamp_target(self._row, target))

    def _start(self, value: int) -> None:
        v = self.values
        self._k.start(self._row, float(v["motion_mode"]), float(v["target_relative_position"]),
                      float(v["target_absolute_position"]))

    def _stop(self, decel: float) -> None:
        s = self._row
        mode = self.mode
        if mode == _TORQUE:
            # no speed profile in torque mode: the current command goes to zero
            self._own("target_current", 0)
            return
        if mode == _SPEED:
            s[K.MODE_SPEED_TARGET] = 0.0
            self._own("target_speed", 0)
        if s[K.G_ACTIVE] != 0.0 or s[K.V_REF]:
            s[K.G_ACTIVE], s[K.G_CONTINUOUS], s[K.G_STOPPING] = 1.0, 0.0, 1.0
            s[K.G_RATE] = float(decel)
        s[K.REPEAT_STOP] = 1.0

    def _own(self, name: str, value: int) -> None:
        """The drive changes one of its own parameters (and the loops see it)."""
        self.values[name] = value
        k = K.PARAMS.get(name)
        if k is not None:
            self._row[k] = float(value)

    def _emergency_stop(self, value: int) -> None:
        s = self._row
        self._stop(max(abs(s[K.V_REF]) / ESTOP_TIME, float(self.values["profile_deceleration"])))
        s[K.MODE_SPEED_TARGET] = 0.0
        self._own("target_current", 0)

    def _stop_repetitive(self, value: int) -> None:
        self._row[K.REPEAT_STOP] = 1.0

    def _reset_output_encoder(self, value: int) -> None:
        s = self._row
        s[K.POS] = s[K.POS] % COUNTS_PER_REV
        s[K.P_REF] = s[K.POS]

    def _speed_command(self, value: int) -> None:
        self._k.target_speed(self._row, float(value))

    # -- physics side -----------------------------------------------------------------------
    def step(self, t: float, dt: float, q: float, qd: float) -> float:
        """Run the drive's loops for the substep ending at ``t`` (length ``dt``) with the joint at
        ``q`` [rad], ``qd`` [rad/s]; return the motor torque at the output [N*m]
        (:func:`joints.sim.erob_kernel.step` on this drive's row; a world steps all rows at once)."""
        return float(self._k.step(self._row, t, dt, q, qd))

    # -- status values (computed when read) -------------------------------------------------
    def _motion_status(self) -> int:
        s = self._row
        if s[K.REPEAT_STOP] != 0.0 and self.values["motion_mode"] == MotionMode.REPETITIVE and s[K.G_ACTIVE] != 0.0:
            return int(MotionStatus.STOP_REPETITIVE)
        return int(MotionStatus.MOVING if self._k.moving(s) else MotionStatus.STOP)


class _StatusRead:
    """A prepared read of a block with the status values (:meth:`ErobFirmware.reader`): one kernel call
    (:func:`joints.sim.erob_kernel.status`), then :meth:`finish` (what the sensors report, saturation) - which
    the one-call exchange (:mod:`joints.sim.erob_exchange`) calls on the values its compiled call computed."""

    __slots__ = ("entries", "fw", "names", "values")

    def __init__(self, fw: ErobFirmware, names: tuple[str, ...], entries: tuple[tuple[int, str, int, int], ...]) -> None:
        self.fw = fw
        self.names = names
        self.entries = entries
        self.values = fw.values

    def repetitive(self) -> bool:
        """The status call's ``repetitive`` argument now."""
        return bool(self.values["motion_mode"] == _REPETITIVE)

    def __call__(self) -> list[int]:
        fw = self.fw
        fw.on_read(self.names)
        return self.finish(fw._k.status(fw._row, self.values["motion_mode"] == _REPETITIVE))

    def finish(self, st: Sequence[int], row: dict[int, float] | None = None) -> list[int]:
        """The read's values from the kernel's status values ``st`` (in :data:`~joints.sim.erob_kernel.STATUS_NAMES`
        order) as the drive reports them; ``row``: the row's columns the sensors see (column -> value) as they
        stood at the read (default: the row now)."""
        fw, values = self.fw, self.values
        if not fw.sensor.ideal:  # what the drive reports (outside the kernel: same bits)
            counts, speed, current = fw._sensed(fw._get if row is None else row.__getitem__)
            st = (*st[:4], counts, *st[5:7], speed, *st[8:10], current, *st[11:])
        # saturate, never wrap: ``lo if v < lo else min(v, hi)``, spelled out (min(v, hi) is v unless hi < v)
        return [values[name] if i < 0 else lo if (v := st[i]) < lo else hi if hi < v else v  # noqa: FURB136
                for i, name, lo, hi in self.entries]

    def finish_row(self, o: Sequence[float], at: int) -> list[int]:
        """:meth:`finish` of the kernel's status values as floats in ``o`` from column ``at`` (in
        :data:`~joints.sim.erob_kernel.STATUS_NAMES` order), followed by the row's time, position, velocity and
        current as they stood at the read (the one-call exchange's output row)."""
        fw = self.fw
        st = list(map(int, o[at:at + _STATUS_COUNT]))
        if not fw.sensor.ideal:  # what the drive reports (outside the kernel: same bits)
            end = at + _STATUS_COUNT
            st[_SENSED_COUNTS], st[_SENSED_SPEED], st[_SENSED_CURRENT] = fw._sensed_at(o[end], o[end + 1], o[end + 2],
                                                                                       o[end + 3])
        values = self.values
        return [values[name] if i < 0 else lo if (v := st[i]) < lo else hi if hi < v else v  # noqa: FURB136
                for i, name, lo, hi in self.entries]


#: the firmware methods a Modbus request reaches, as defined (captured when this module is imported): a one-call
#: exchange (:mod:`joints.sim.erob_exchange`) runs only while none of them is replaced
STOCK = tuple((ErobFirmware, name, getattr(ErobFirmware, name)) for name in (
    "write_many", "on_write", "on_read", "check_write", "frame_received", "_start", "_speed_command", "set",
    "reader", "_store"))
