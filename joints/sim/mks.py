"""The MKS SERVO42D/57D firmware: a closed-loop stepper drive by parameter name, without a protocol.

Rule: the firmware IS the drive. It holds the parameters of
:data:`~joints.devices.mks.params.MKS_PARAMS` (by name), executes the commands of the manual's
Parts 5 and 6 (:meth:`MksFirmware.execute`: all fields of one command at once, the reply status as
the result), runs the run state machine of :mod:`joints.devices.mks.state`, and every physics
substep generates its reference and turns it into a motor torque. It never sets a position. The
native front (:mod:`joints.sim.mks_front`) and the Part 8 Modbus front
(:mod:`joints.sim.mks_modbus_front`) reach it by the same names. No wall clock: time advances only
through :meth:`MksFirmware.step`. Everything is motor side (rad, rad/s, N*m); a lead screw is the
world's business.

The model
    * Reference generator: the speed *value* changes by 1 every ``(256 - acc) x 50 us`` (acc 0: at
      once), converted to motor rpm by the subdivision (6.1) and clamped to the work mode's maximum
      (OPEN 400, CLOSE 1500, vFOC 3000 rpm). Position moves decelerate in time to end exactly on
      their target (pulses: a whole number of microsteps; axis: a whole encoder count); below the
      last speed step they creep at 1 rpm. In closed modes a move is complete (status 2, 0xF1
      stop) once the shaft is within :data:`IN_POSITION` of the target and at rest, or
      :data:`SETTLE_TIMEOUT` after the reference got there.
    * Motor: the torque available is the profile's stepper curve, ``min(Kt x I, holding torque)``
      falling linearly to zero at the back-EMF speed (:meth:`~joints.devices.mks.profile.MksProfile.available_torque`)
      with I the working current (0x83; in OPEN and CLOSE modes at standstill the holding
      percentage 0x9B of it). A command faster than the motor can go saturates there: the speed
      read back (0x32) is the rotor's, never the command.
    * Closed modes (CLOSE, vFOC): a position servo on the encoder (bandwidth :data:`SERVO_BANDWIDTH`,
      integral action) drives the rotor to the reference; a lagging rotor catches up (no lost
      steps). OPEN: the field follows the microstep-quantised reference and pulls the rotor with
      ``T sin(50 x angle)`` (50 pole pairs of a 1.8 degree motor): a load beyond the available torque
      makes the rotor slip whole electrical cycles (4 full steps) - lost steps, never corrected.
      Both are integrated implicitly against the inertia the drive is coupled to, so they stay
      stable at the world's time step.
    * Encoder: 16384 counts per turn, floor-quantised; the axis (0x31) is counted from a zero set
      at power-on (the angle within the turn of the absolute encoder), by 0x92 or by homing.
    * Locked-rotor protection (0x88 on, closed modes): the shaft is released when the position error
      stays above the profile's ``stall_error`` for ``stall_time`` (facts: ">180 degrees within
      300 ms"); 0x3E reports it, OUT_1 drops (57D), 0x3D releases it.
    * End stops: the world tells the twin where the switches trigger (:meth:`set_end_stops`, motor
      angles from the MuJoCo geometry). IN_1 is the home / left switch at the low (CW, negative)
      end, IN_2 the right switch at the high end (the 57D; the 42D with limit remap 0x9E). A
      switch reads the configured effective level (0x90 HmTrig) while triggered. EndLimit (0x90)
      stops a motion into a triggered switch at once: completion status 3.
    * Homing (0x91): limit switch - leave the switch if it is already active, run at HmSpeed in
      HmDir until IN_1 triggers, stop, that is the axis zero (with EndLimit on the shaft is then
      released: 5.3 note 2); 'noLimit' (0x94 mode 1) - run with the torque of Hm_Ma until the
      rotor stalls, back off retValue counts, zero there.
    * 0_Mode (0x9A): "Set 0" stores the absolute encoder's present angle within the turn (flash; 0x92
      and homing do not move it); at power-on the motor returns to it (DirMode in 0_Dir, NearMode the
      shorter way, less than one turn, none within :data:`AT_ZERO`); 0x3B status1 reports 0 going,
      1 success, 2 stopped first.
    * Save/clean speed mode (0xFF): C8 stores the speed-mode fields in flash; at power-on a saved
      speed mode runs (in a serial work mode).
    * Settings (0x82-0x9E) are kept in flash like the drive's menu, so they survive a power cycle;
      0x3F restores the factory defaults (the configured address and protocol included) and
      reboots, the encoder then needs calibrating (0x80) before motion; 0x41 reboots.

Firmware profiles (:mod:`joints.devices.quirks`, ``firmware`` of the joint; default the newest)
    The twin has what its firmware has: :meth:`MksFirmware.supports` says whether a parameter of a
    later firmware (:data:`~joints.devices.mks.params.FEATURE_OF`) exists; the fronts treat the
    others as unknown commands. V1.0.9's 0x40 reports calibration, the hardware version (1
    S42D_485, 3 S57D_485) and the profile's version. V1.0.9's heartbeat protection (0x98): while a
    motion runs and no frame addressed to the drive arrived for the set time (0 = off), the drive
    stops at once, as 0xF7 does (:attr:`MksFirmware.heartbeat_trips` counts it; the shaft stays
    enabled and held). Like the other settings it is kept in flash (the manual does not say).
    V1.0.9's 0x01 timed returns sample the read's values every period on the simulated clock
    (:meth:`MksFirmware.set_timed_return`); the front sends them as that read's reply, unasked.
    V1.0.6's 0x36 writes the outputs: a port the host wrote (mask 1) reads the written level in 0x34 from
    then on (OUT_1 no longer shows the 57D's stall indication); masks 0 and 2 leave it (the manual's "do
    not write" and "remains unchanged" do the same here); the written levels are lost at power-off.
    V1.0.6's 0x9D position-error protection: when the position error stays above Errors (28000 per turn)
    for Tim x 15 ms (closed modes, like the locked-rotor protection), the drive protects: the motion ends
    without a completion frame (the state machine's PROTECTION), the shaft is released, 0x3E reads 1
    (:attr:`MksFirmware.protection_cause` says which protection), 0x3D or an En pulse
    (:meth:`MksFirmware.en_pulse`) releases it. g0Enable: the 0_Mode zero return no longer runs at
    power-on but on an En pulse of about 200 ms in a pulse work mode.
    V1.0.9's 0x99 pulse divider (57D only; a 42D answers status 0): OUT_2 (0x34 bit 3) reads divLevel
    toggled once every divPeriod pulses of the shaft's travel since the command (:meth:`MksFirmware.divider_level`;
    signed travel and the start point are our reading), off below 100. V1.0.9's 0x9F (28D/35D/42D only; a
    57D answers status 0): IN_1 as an output reads the level 0x36 bit 2 writes, whatever OUT1_mask, and no
    switch (the home / left limit on IN_1 is not seen unless 0x9E remaps it to En).
    V1.0.8's 0x95 (profile v1.0.9): a position move (0xFD/0xFE/0xF4/0xF5) in a closed mode completes only
    while the position error is below the threshold (65536 per turn, default 200 = 1.1 degrees) - a
    necessary condition on top of the settle rule above, so a shaft held off the target by more never
    completes (the older profiles complete after the settle timeout); threshold off: the settle rule.
    V1.0.7's 0xF6 run time (profile v1.0.9): the speed-mode motion stops by itself that long after the
    command arrived, decelerating with the command's acc (acc 0: at once), and ends with the "run
    complete" frame (status 2) like a stop command's.
    V1.0.8's IAP control (0x50, profile v1.0.9): 02 / 03 enter / leave the silent state (the drive neither
    answers nor executes any command but 0x50: "does not respond", our reading). 01 answers status 1,
    then the drive releases the shaft and sits in its boot loader (:attr:`MksFirmware.boot_loader`),
    answering nothing: the upgrade file's protocol is in a separate MKS document, so the twin cannot
    take a firmware file - a power cycle returns it to its firmware unchanged (a real drive after an
    interrupted upgrade may not come back).
    V1.0.7's 0x83 not saved (trailing 00; Modbus bit 15): the working current changes at once (the torque
    the motor has), flash keeps the last saved one, so a power cycle brings that back; status 2.
    V1.0.7's 0x3B second status (homing): 2 until the first go home (0x91; the Modbus manual: "not
    returned to zero"), 0 while it runs, 1 once homed, 2 when a stop, 0xF7, a disable or a protection
    ended it first.
    V1.0.8's synchronization (Part 12.4, profile v1.0.9): with 0x4A on, a run command (not a stop) is
    checked, its fields taken and the command held, answered with run status 5; the broadcast 0x4B
    starts it (:meth:`MksFirmware.sync_execute`). A second run command before 0x4B replaces the held one
    (the manual does not say; our choice); stops, 0xF7 and disabling act at once and drop it; a power cycle
    drops it too (the flag itself is a setting, kept in flash).
    V1.0.9's hm_mode 2 "single lap to zero" (0x94; docs/mks-firmware.md, assumptions S1-S7): go home runs
    the 0_Mode return above (its zero, direction and speed; status 0 without a zero), reports 0xF1 homing,
    resets the axis to 0 on arrival and ends with go home's completion; 0x3B status1 tracks it. A
    firmware before V1.0.9 takes hm_mode 0-1 only (:meth:`MksFirmware.check_write`).
    V1.0.9's coordinate homing (0x91 goZeroMode 01, FC06 0x0091 = 2) is a position move to axis 0 at
    HmSpeed without a search (the manuals' "directly runs to the coordinate zero point"); it ends with go
    home's completion and leaves the zero where it is. V1.0.9's user ID (0x42) is kept in flash. V1.0.8's
    0x00 answers a set command's data from what the twin holds (the front), FF FF for a command.
    V1.0.6's 0x46/0x47/0x48 (:mod:`joints.devices.mks.blocks`) write/read the same settings and
    statuses as the single commands; a 0x46 with any value out of range changes nothing (status 0).

Choices where the manual is silent (documented here, see also :mod:`joints.devices.mks.state`)
    * The drive is enabled at power-on (the Part 7 examples run without 0xF3); motion and 0xF3 enable
      need a serial work mode (0xF3 disable always works) and a calibrated encoder; a run command
      while disabled fails (status 0).
    * A stop command with any run code (speed 0) stops whatever motion runs.
    * In speed mode the reference is held at most :data:`SPEED_MODE_LEAD` ahead of a rotor that
      cannot follow (the protection, when on, still sees the error grow beyond 180 degrees).
    * A reversal in speed mode, or an 0xF5 update behind a running move, decelerates to standstill
      first, then runs the new way.
    * 0_Speed 0..4 = :data:`ZERO_MODE_RPM`; homing runs without ramp; calibration takes
      :data:`CALIBRATION_TIME` and answers 0 at once, 1 later; a saved speed mode wins over 0_Mode
      at power-on; 0x3B reads 1 when 0_Mode is off; the locked-rotor protection watches closed
      modes only (OPEN has no position feedback); save/clean completes :data:`FLASH_TIME` later.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable, Mapping
from dataclasses import dataclass

from joints.devices.mks import blocks
from joints.devices.mks import state as st
from joints.devices.mks.native import Command
from joints.devices.mks.params import FEATURE_OF, VALUE_FEATURE_OF
from joints.devices.mks.profile import MksProfile
from joints.devices.params import Access, ParamSet
from joints.devices.quirks import (
    MKS_ALL_PARAMETERS,
    MKS_POSITION_ERROR_PROTECTION,
    MKS_POSITION_THRESHOLD,
    MKS_SYNC,
    MKS_TIMED_RETURNS,
    FirmwareProfile,
    firmware_profile,
)
from joints.errors import CommandError, ParameterRefused, Refusal
from joints.sim.firmware import Firmware
from joints.sim.sensors import Sensor, model_of

__all__ = ["CALIBRATION_TIME", "EN_PULSE", "FLASH_TIME", "POSITION_ERROR_PER_TURN", "POSITION_ERROR_TICK",
           "POSITION_THRESHOLD_PER_TURN", "RUN_TIME_UNIT", "SERVO_BANDWIDTH", "SPEED_MODE_LEAD", "SYNC_RECEIVED", "ZERO_MODE_RPM",
           "Completion", "MksFirmware", "TimedReturn"]

TAU = 2.0 * math.pi
RPM = TAU / 60.0
COUNTS = st.ENCODER_COUNTS_PER_TURN
POLE_PAIRS = 50  #: 1.8 degree motor: 200 full steps = 50 electrical cycles
SERVO_BANDWIDTH = 600.0  #: rad/s, closed-loop position servo
SERVO_DAMPING = 1.0
SPEED_MODE_LEAD = TAU  #: rad: how far the speed-mode reference may run ahead of the rotor
HOME_STALL = 0.25  #: rad of error that counts as "blocked" in 'noLimit' homing
IN_POSITION = 1.5 * TAU / COUNTS  #: rad: a closed-loop move is complete once the shaft is this close ...
IN_POSITION_SPEED = 0.5 * RPM  #: ... and this slow (rad/s),
SETTLE_TIMEOUT = 0.3  #: s - or this long after its reference arrived (a load may hold it off)
CALIBRATION_TIME = 2.0  #: s
FLASH_TIME = 0.01  #: s from a save/clean reply to its completion
#: counts: a single-turn zero return this close to its zero does not turn (the zero is a floored count and a move
#: ends within IN_POSITION of its target; our choice, the manual says "returns to" only)
AT_ZERO = 2.0
ZERO_MODE_RPM = (15, 30, 60, 120, 240)  #: 0_Speed 0 (slowest) .. 4 (fastest)
POSITION_ERROR_PER_TURN = 28000  #: 0x9D Errors: "When Errors = 28000, the motor is misaligned by 360 degrees"
POSITION_ERROR_TICK = 0.015  #: s per 0x9D Tim unit ("approximately equal to 15 ms")
POSITION_THRESHOLD_PER_TURN = 65536  #: 0x95 values: "The maximum value is 65535, which is 360 degrees"
RUN_TIME_UNIT = 0.01  #: s per 0xF6 runTime unit (V1.0.7: "uints: 10ms")
SYNC_RECEIVED = int(st.RunStatus.SYNC_RECEIVED)  #: "Data has received for Synchronous mode" (0x4A on, V1.0.8)
EN_PULSE = (0.15, 0.3)  #: s: the En pulse that triggers the 0x9D zero return ("about 200 ms"; our window)
_RUN_CODES = {int(c): c for c in (Command.SPEED_MODE, Command.POSITION_MODE1_RELATIVE_PULSES,
                                   Command.POSITION_MODE2_ABSOLUTE_PULSES, Command.POSITION_MODE3_RELATIVE_AXIS,
                                   Command.POSITION_MODE4_ABSOLUTE_AXIS)}
#: run command -> the prefix of its parameters
_PREFIX = {0xF6: "speed_mode", 0xFD: "position_mode1", 0xFE: "position_mode2", 0xF4: "position_mode3",
           0xF5: "position_mode4"}
_SET = st.SetStatus
_RUN = st.RunStatus


@dataclass(frozen=True, slots=True)
class Completion:
    """A later status the drive sends by itself (the front decides whether it goes on the wire)."""

    time: float
    function: int  #: the command it ends (0xF6, 0xFD, 0x91, 0x80, 0xFF ...)
    status: int  #: RunStatus 2/3 (CalibrationStatus 1/2 for 0x80)
    answered: bool  #: the command came to this drive alone (not broadcast, group or long packet)


@dataclass(frozen=True, slots=True)
class TimedReturn:
    """A read the drive sends by itself (V1.0.9 0x01): the values of ``names`` sampled at ``time``."""

    time: float
    code: int  #: the read command whose reply it is
    values: tuple[int, ...]


@dataclass
class _Motion:
    """The reference generator's job."""

    kind: str  #: "speed" | "move" | "home" | "zero"
    function: int  #: the command code that started it (completion frames carry it)
    answered: bool
    goal: int = 0  #: speed value to reach (magnitude)
    acc: int = 0
    direction: int = 1  #: +1 CCW, -1 CW (speed mode and homing)
    target: float = 0.0  #: rad (moves)
    stopping: bool = False
    phase: str = ""  #: homing: "leave" | "seek" | "back"
    arrived: float = -1.0  #: when the reference reached the target (the rotor settles into the window)
    until: float = math.inf  #: speed mode with a run time (0xF6, V1.0.7): when it stops by itself


class MksFirmware(Firmware):
    """One MKS SERVO42D/57D, coupled to one simulated motor shaft (see the module docstring)."""

    q: float  #: shaft angle [rad]
    qd: float  #: shaft speed [rad/s]
    r: float  #: reference [rad]
    enc_zero: float
    raw_zero: float
    pulse_zero: float
    zero_status: int

    def __init__(self, profile: MksProfile, params: ParamSet, address: int = 1, *, inertia: float | None = None,
                 modbus: bool = False, values: Mapping[str, int] | None = None,
                 firmware: FirmwareProfile | str | None = None) -> None:
        #: the firmware version this drive runs (its added commands; joints.devices.quirks)
        self.firmware = firmware if isinstance(firmware, FirmwareProfile) else firmware_profile("mks", firmware)
        factory = {"working_current": round(profile.default_working_current * 1000),
                   "home_current": round(profile.default_home_current * 1000), "motor_enable": 1}
        super().__init__(params, values=factory)
        self.profile = profile
        #: what the drive's owner set on the menu (flash): address, protocol, then ``values``
        self.saved = {"slave_address": address, "modbus_rtu": int(modbus), **dict(values or {})}
        self.values.update(self.saved)
        self.power_on_values = dict(self.values)
        self.inertia = inertia if inertia is not None else profile.rotor_inertia  #: kg*m^2 at the shaft
        #: the drive's sensors (joints.sim.sensors): what a read of the encoder and the speed reports
        self.sensor = Sensor(model_of(profile), f"mks:{address}", COUNTS / TAU)
        self.sensors = (self.sensor,)
        self.time = 0.0
        #: flash beyond the parameters
        self.calibrated = True
        self.zero_point: int | None = None  #: 0_Mode zero: counts within the turn of the absolute encoder
        self.saved_speed: tuple[int, int, int] | None = None  #: (direction bit, speed value, acc)
        self.end_stops: tuple[float | None, float | None] = (None, None)  #: trigger angles [rad]
        #: completion statuses waiting for a front
        self.completions: deque[Completion] = deque()
        self._persistent = frozenset(p.name for p in params if p.access in (Access.W, Access.RW)  # (RW: 0x42 user ID)
                                     and p.name != "motor_enable")
        self.computed.update({
            "encoder_carry": lambda: self._sensed_counts() // COUNTS,
            "encoder_value": lambda: self._sensed_counts() % COUNTS,
            "encoder_addition": self._sensed_counts,
            "real_time_speed": lambda: round(self._sensed_speed() / RPM),
            "number_of_pulses": lambda: round((self.r - self.pulse_zero) / self.rad_per_pulse),
            "io_status": self.io_status,
            "angle_error": lambda: round((self.r - self.q) * st.ANGLE_ERROR_PER_TURN / TAU),
            "en_pin_status": lambda: int(self.enabled),
            "go_back_to_zero_status": lambda: self.zero_status,
            "homing_status": lambda: self.home_status,
            "protection_state": lambda: int(self.protected),
            "motor_status": lambda: int(self.motor_status()),
            "version_information": self.version_information,
            "raw_encoder_value": lambda: math.floor((self.q - self.raw_zero) * COUNTS / TAU + 1e-9),
        })
        #: V1.0.9 0x01 timed returns: read command -> (its parameter names, period [s], next due time)
        self.timed: dict[int, tuple[tuple[str, ...], float, float]] = {}
        self.returns: deque[TimedReturn] = deque()  #: sampled, waiting for a front
        self.heartbeat_trips = 0  #: motions the heartbeat protection stopped
        self.heartbeat_tripped_at = -1.0  #: when it last did [s]
        self._last_frame = 0.0  #: when the last frame addressed to this drive arrived
        self._handlers: dict[int, Callable[[Mapping[str, int], bool], int]] = {
            Command.RELEASE_PROTECTION_STATE: self._release,
            Command.RESTORE_DEFAULT_PARAMETERS: self._restore,
            Command.RESTART_MOTOR: self._restart,
            Command.CALIBRATE_ENCODER: self._calibrate,
            Command.SET_WORK_MODE: self._work_mode,
            Command.GO_HOME: self._go_home,
            Command.SET_CURRENT_AXIS_TO_ZERO: self._set_zero,
            Command.SET_ZERO_MODE: self._zero_mode,
            Command.ENABLE_MOTOR: self._enable,
            Command.EMERGENCY_STOP: self._emergency_stop,
            Command.SAVE_CLEAN_SPEED_MODE: self._save_clean,
            Command.WRITE_IO_PORT: self._write_io,
            Command.SET_PULSE_DIVIDER: self._pulse_divider,
            Command.IAP_CONTROL: self._iap,
            **{code: self._run_command for code in _RUN_CODES},
        }
        self.q = 0.0
        self.qd = 0.0
        self.enc_zero = 0.0  #: rad where the encoder axis counts 0
        self.raw_zero = 0.0  #: rad where the raw encoder value (0x35) counts 0: the power-on turn
        self.pulse_zero = 0.0  #: rad where the pulse position counts 0
        self._calibrating_answered = True
        self._reset_state()

    # -- power ----------------------------------------------------------------------------------
    def _reset_state(self) -> None:
        v = self.values
        self.enabled = bool(v["motor_enable"])
        self.protected = False
        self.protection_cause = ""  #: "locked-rotor" (0x88) or "position-error" (0x9D) while protected
        self._perr_since = -1.0
        self.outputs: dict[int, int] = {}  #: OUT_1 / OUT_2 levels the host wrote (0x36, V1.0.6)
        self.in1_level = 0  #: IN_1's level while 0x9F makes it an output (V1.0.9), written by 0x36 bit 2
        self.divider_origin = self.q  #: rad where the 0x99 pulse divider (V1.0.9) counts from: power-on or the command
        #: the run command 0x4A holds until 0x4B (V1.0.8): (code, its fields, answered); when 0x4B last started one
        self.sync_held: tuple[int, dict[str, int], bool] | None = None
        self.sync_started_at = -1.0
        self.silent = False  #: IAP silent state (0x50 02): only 0x50 is heard
        self.boot_loader = False  #: in the IAP boot loader (0x50 01): hears nothing the twin can answer
        self.run_state = st.RunState.IDLE
        self.motion: _Motion | None = None
        self.speed = 0  #: present speed value of the reference (magnitude)
        self.ramp_goal = 0  #: the speed value the ramp heads for
        self.moving_dir = 1
        self._ramp_t = 0.0
        self.r = self.q  #: reference [rad]
        self.v_ref = 0.0  #: rad/s
        self._integral = 0.0
        self._stall_since = -1.0
        self._calibrating_until = -1.0
        self._reboot_at: float | None = None
        self.zero_status = int(st.GoBackToZeroStatus.SUCCESS)
        self.home_status = int(st.GoBackToZeroStatus.FAIL)  #: 0x3B status2 (V1.0.7): 2 "not returned to zero" yet
        self._power_on = True  #: the axis zero and the power-on jobs wait for the first shaft angle
        self.completions.clear()
        self._cache()

    def power_cycle(self) -> None:
        """Power off/on: flash survives (settings, 0_Mode zero, saved speed mode), the rest restarts."""
        super().power_cycle()
        self.timed.clear()  # timed returns are not kept (the manual does not say; our choice)
        self.returns.clear()
        self._reset_state()
        self.sensor.reseed()  # the sensors' noise restarts with the drive: a world reset is reproducible

    def _cache(self) -> None:
        v = self.values
        self.mode = st.WorkMode(v["work_mode"])
        self.microsteps = v["microsteps"]
        self.rad_per_pulse = TAU / st.pulses_per_turn(self.microsteps)
        self.current = v["working_current"] * 1e-3

    def place(self, q: float) -> None:
        """The shaft is at ``q`` [rad] and at rest (start state): reference and encoder follow."""
        self.q, self.qd = q, 0.0
        if self._power_on:
            self._powered(q)
        self.r = q
        self.v_ref = 0.0
        self._integral = 0.0

    def _powered(self, q: float) -> None:
        """The first shaft angle after power-on: the axis counts from the turn the absolute encoder is in."""
        self._power_on = False
        self.enc_zero = TAU * math.floor(q / TAU + 1e-12)
        self.pulse_zero = self.enc_zero
        self.raw_zero = self.enc_zero
        self.r = q
        if self.saved_speed is not None and self.mode.serial and self.calibrated:
            direction, speed, acc = self.saved_speed
            self.enabled = True
            self._start(_Motion("speed", Command.SPEED_MODE, False, goal=self._clamp_value(speed), acc=acc,
                                direction=1 if direction == st.RunDirection.CCW else -1))
        elif self.values["zero_mode"] and self.zero_point is not None and not self.values["en_trigger_zero_return"]:
            self._zero_return()

    def set_end_stops(self, low: float | None, high: float | None) -> None:
        """Where the end-stop switches trigger [rad, motor side]: IN_1 at or below ``low``, IN_2 at or above ``high``."""
        self.end_stops = (low, high)

    # -- what the fronts call -----------------------------------------------------------------------
    def supports(self, name: str) -> bool:
        """Whether this firmware has parameter ``name`` (the later firmware's ones need their feature)."""
        feature = FEATURE_OF.get(name)
        return feature is None or feature in self.firmware.features

    def frame_received(self) -> None:
        """A frame for this drive arrived: the heartbeat protection's food."""
        self._last_frame = self.time

    @property
    def has_blocks(self) -> bool:
        """Firmware V1.0.6+: 0x46/0x47/0x48 read and write all parameters."""
        return MKS_ALL_PARAMETERS in self.firmware.features

    def all_parameters(self) -> bytes:
        """0x47: the 34 configuration bytes (the "set 0" byte reads FF, reserved)."""
        data = bytearray(blocks.pack(blocks.ALL_PARAMETERS, self.values, 34))
        for name, offset, n in blocks.ALL_PARAMETERS:
            if name in blocks.NOT_READ_BACK:
                data[offset:offset + n] = b"\xff" * n
        return bytes(data)

    def write_all_parameters(self, data: bytes) -> int:
        """0x46: every configuration setting at once, as the single set commands would (all checked first:
        a value out of range fails the whole block, status 0)."""
        values = blocks.unpack(blocks.ALL_PARAMETERS, data)
        try:
            blocks.check(self.params, values)
            for name, value in values.items():
                self.check_write(name, value)
        except (CommandError, ParameterRefused):
            return int(_SET.FAIL)
        mode = values["work_mode"] != self.values["work_mode"]
        if values["group_address"] == 0:  # "no group" (the power-on value; 0x8D itself takes 1-255)
            self.values["group_address"] = self.saved["group_address"] = 0
        self.write_many([(n, v) for n, v in values.items() if not (n == "group_address" and v == 0)])
        if mode:
            self._work_mode({}, True)
        self.zero_point = self.turn_counts() if values["zero_mode_set_zero"] else self.zero_point
        return int(_SET.SUCCESS)

    def all_status(self) -> bytes:
        """0x48: the 28 status bytes."""
        zero = self.zero_status
        values = {"motor_status": int(self.motor_status()), "encoder_addition": self.counts(),
                  "real_time_speed": round(self.qd / RPM), "io_status": self.io_status(),
                  "number_of_pulses": self.read("number_of_pulses"), "raw_encoder_value": self.read("raw_encoder_value"),
                  "angle_error": self.read("angle_error"), "en_pin_status": int(self.enabled),
                  "single_turn_zero_status": zero, "protection_state": int(self.protected),
                  "go_back_to_zero_status": zero}
        return blocks.pack(blocks.ALL_STATUS, values, 28)

    def set_timed_return(self, code: int, names: tuple[str, ...], milliseconds: int) -> int:
        """0x01 (V1.0.9): sample ``names`` (read command ``code``) every ``milliseconds`` and send them; 0 stops it.
        Status 0 for a firmware without it or a command that is not a read."""
        if MKS_TIMED_RETURNS not in self.firmware.features or not names or not all(
                self.params[n].access is Access.R for n in names):
            return int(_SET.FAIL)
        if milliseconds:
            self.timed[code] = (names, milliseconds * 1e-3, self.time + milliseconds * 1e-3)
        else:
            self.timed.pop(code, None)
        return int(_SET.SUCCESS)

    def take_returns(self, now: float) -> list[TimedReturn]:
        """Timed returns sampled by ``now`` (the front turns them into frames)."""
        out: list[TimedReturn] = []
        while self.returns and self.returns[0].time <= now + 1e-12:
            out.append(self.returns.popleft())
        return out

    def version_information(self) -> int:
        """0x40: calibration (b31-b28), hardware version (b27-b24: 1 S42D_485, 3 S57D_485), firmware."""
        hardware = 3 if self.profile.model == "SERVO57D" else 1
        major, minor, patch = (tuple(self.firmware.version) + (0, 0, 0))[:3]
        return (int(self.calibrated) << 28) | (hardware << 24) | (major << 16) | (minor << 8) | patch

    def check_write(self, name: str, value: int) -> None:
        """A value a later firmware added to the range (0x94 hm_mode 2, V1.0.9) is out of range before it."""
        feature = VALUE_FEATURE_OF.get((name, value))
        if feature is not None and feature not in self.firmware.features:
            raise ParameterRefused(Refusal.OUT_OF_RANGE, name, f"{value} is {feature}, not in firmware "
                                   f"{self.firmware.firmware}")

    def on_write(self, name: str, value: int) -> None:
        if name in self._persistent and name != "working_current_unsaved":
            self.saved[name] = value  # the drive keeps its menu settings in flash
        if name in ("work_mode", "microsteps", "working_current"):
            self._cache()

    def execute(self, command: int, values: Mapping[str, int], *, answered: bool = True) -> int:
        """Execute one command with all of its fields; the reply status (0 fail, 1 success / started ...).

        ``answered``: the command was addressed to this drive alone (its completion may be sent).
        Raises :class:`~joints.errors.ParameterRefused` when a value is unknown, not writable or out of
        range (the front answers "fail" or a Modbus exception). A command the drive cannot carry out in its
        present state (:meth:`_refusal`) gets status 0 and changes nothing, its fields included.
        """
        refused = self._refusal(command, values)
        if refused is not None:
            return refused
        flash = self.saved.get("working_current")
        if values:
            self.write_many(list(values.items()))
        if values.get("working_current_unsaved"):  # 0x83 while running, not saved (V1.0.7)
            if flash is None:
                self.saved.pop("working_current", None)
            else:
                self.saved["working_current"] = flash
            return int(_SET.SUCCESS_UNSAVED)
        if (command in _PREFIX and MKS_SYNC in self.firmware.features and self.values["sync_enable"]
                and self.values[f"{_PREFIX[command]}_speed"] != 0):
            self.sync_held = (command, dict(values), answered)  # 0x4A on: wait for 0x4B (the last one wins)
            return SYNC_RECEIVED
        handler = self._handlers.get(command)
        return handler(values, answered) if handler is not None else int(_SET.SUCCESS)

    def _refusal(self, command: int, values: Mapping[str, int]) -> int | None:
        """Status 0 for a command the drive cannot carry out now - enable outside the serial work modes (the
        pulse interface's En pin rules there), a motion (go home, a run command other than its stop) while it
        cannot run; None: it executes."""
        if command == Command.ENABLE_MOTOR:
            return int(_SET.FAIL) if values.get("motor_enable") and not self.mode.serial else None
        if command == Command.SET_PULSE_DIVIDER:  # "only for 57D" (V1.0.9 6.4): the model with IN_2
            return None if self.profile.limit_inputs >= 2 else int(_SET.FAIL)
        if command == Command.SET_IN1_PORT_MODE:  # "only applies to ... 28D/35D/42D" (V1.0.9 6.2): IN_1 alone
            return None if self.profile.limit_inputs == 1 else int(_SET.FAIL)
        if command == Command.GO_HOME and not values.get("go_home_mode") and not self._single_lap_ready():
            return self._refuse()  # single lap to zero with no single-turn zero set (assumption S5)
        if command == Command.GO_HOME or (command in _PREFIX and values.get(
                f"{_PREFIX[command]}_speed", self.values[f"{_PREFIX[command]}_speed"]) != 0):
            return None if self._can_run() else self._refuse()
        return None

    def _single_lap_ready(self) -> bool:
        """Whether go home can run: any method but single lap to zero, or a 0_Mode direction and zero to run to."""
        return (self.values["home_mode"] != st.HomeMode.SINGLE_LAP
                or (bool(self.values["zero_mode"]) and self.zero_point is not None))

    # -- commands -----------------------------------------------------------------------------------
    def _release(self, values: Mapping[str, int], answered: bool) -> int:
        if self.protected:
            self.protected = False
            self.protection_cause = ""
            self._hold()
        return int(_SET.SUCCESS)

    def _restore(self, values: Mapping[str, int], answered: bool) -> int:
        self.saved = {}
        self.zero_point = None
        self.saved_speed = None
        self.calibrated = False  # "After restored the parameters ... need to calibrate the motor"
        self._reboot_at = self.time
        return int(_SET.SUCCESS)

    def _restart(self, values: Mapping[str, int], answered: bool) -> int:
        self._reboot_at = self.time
        return int(_SET.SUCCESS)

    def _calibrate(self, values: Mapping[str, int], answered: bool) -> int:
        if self.motion is not None:
            self._complete(Command.CALIBRATE_ENCODER, int(st.CalibrationStatus.FAIL), answered)
        else:
            self._calibrating_until = self.time + CALIBRATION_TIME
            self._calibrating_answered = answered
        return int(st.CalibrationStatus.CALIBRATING)

    def _work_mode(self, values: Mapping[str, int], answered: bool) -> int:
        self._end(st.RunEvent.STOP_NOW, quiet=True)
        self._hold()  # the new mode starts from where the shaft is
        return int(_SET.SUCCESS)

    def _enable(self, values: Mapping[str, int], answered: bool) -> int:
        on = bool(values["motor_enable"])  # (not in a pulse work mode: :meth:`_refusal`)
        if on and not self.enabled:
            self.enabled = True
            self._hold()
        elif not on:
            self.enabled = False
            self.sync_held = None
            self._end(st.RunEvent.EMERGENCY_STOP, quiet=True)
        return int(_SET.SUCCESS)

    def _emergency_stop(self, values: Mapping[str, int], answered: bool) -> int:
        self.sync_held = None
        self._end(st.RunEvent.EMERGENCY_STOP)
        self._hold()
        return int(_SET.SUCCESS)

    def _set_zero(self, values: Mapping[str, int], answered: bool) -> int:
        self.enc_zero = self.q
        self.pulse_zero = self.q
        return int(_SET.SUCCESS)

    def _zero_mode(self, values: Mapping[str, int], answered: bool) -> int:
        self.zero_point = self.turn_counts() if values["zero_mode_set_zero"] else None
        return int(_SET.SUCCESS)

    def _save_clean(self, values: Mapping[str, int], answered: bool) -> int:
        v = self.values
        if values["save_clean_speed_mode_parameter"] == st.SpeedModeParameter.SAVE:
            self.saved_speed = (v["speed_mode_direction"], v["speed_mode_speed"], v["speed_mode_acc"])
        else:
            self.saved_speed = None
        self.completions.append(Completion(self.time + FLASH_TIME, Command.SAVE_CLEAN_SPEED_MODE,
                                           int(_RUN.COMPLETE), answered))
        return int(_RUN.STARTED)

    def sync_execute(self) -> bool:
        """0x4B (V1.0.8): start the run command held since 0x4A made it wait; whether one was held."""
        held, self.sync_held = self.sync_held, None
        if held is None or MKS_SYNC not in self.firmware.features:
            return False
        command, values, answered = held
        if self._refusal(command, values) is not None:  # it cannot run now (disabled meanwhile ...)
            return False
        self.sync_started_at = self.time
        self._run_command(values, answered)
        return True

    def en_pulse(self, width: float = 0.2) -> bool:
        """The En line pulsed for ``width`` s, ending now (a hardware input, like :meth:`set_end_stops`).

        V1.0.6: a pulse releases a protection (version notes, "It can release the protection status by
        En"); with 0x9D g0Enable on, in a pulse work mode (CR_*, where the En line rules), a pulse of
        :data:`EN_PULSE` ("about 200 ms") starts the single-turn zero return of 0_Mode. Returns whether
        it did anything. A firmware before V1.0.6 ignores it."""
        if MKS_POSITION_ERROR_PROTECTION not in self.firmware.features:
            return False
        if self.protected:
            self.protected = False
            self.protection_cause = ""
            self._hold()
            return True
        if (self.values["en_trigger_zero_return"] and not self.mode.serial and self.values["zero_mode"]
                and self.zero_point is not None and EN_PULSE[0] <= width <= EN_PULSE[1] and self.motion is None):
            self._zero_return()
            return True
        return False

    def _iap(self, values: Mapping[str, int], answered: bool) -> int:
        cmd = values["iap_control"]
        if cmd == 1:  # "the motor will automatically restart and enter IAP mode 2, waiting to receive the file"
            self.enabled = False
            self._end(st.RunEvent.EMERGENCY_STOP, quiet=True)
            self.boot_loader = True
        else:
            self.silent = cmd == 2
        return int(_SET.SUCCESS)

    def hears(self, command: int) -> bool:
        """Whether a command reaches the firmware: not in the boot loader, only 0x50 in the silent state."""
        return not self.boot_loader and (not self.silent or command == Command.IAP_CONTROL)

    def _write_io(self, values: Mapping[str, int], answered: bool) -> int:
        for port in (1, 2):
            if values[f"write_io_out{port}_mask"] == 1:
                self.outputs[port] = values[f"write_io_out{port}"]
        if self.values["in1_port_mode"]:  # IN_1 an output (0x9F, V1.0.9): bit 2 "without being restricted by OUT1_mask"
            self.in1_level = values["write_io_out1"]
        return int(_SET.SUCCESS)

    def _pulse_divider(self, values: Mapping[str, int], answered: bool) -> int:
        self.divider_origin = self.q  # the divider counts from the command (our reading)
        return int(_SET.SUCCESS)

    def divider_level(self) -> int | None:
        """OUT_2 as the 0x99 pulse divider output (V1.0.9, 57D): divLevel, toggled once every divPeriod pulses
        of the shaft's travel since the command (signed: back over a toggle point toggles back); None: off
        (divPeriod below 100)."""
        period = self.values["pulse_divider_period"]
        if period < 100 or self.profile.limit_inputs < 2:
            return None
        pulses = (self.q - self.divider_origin) / self.rad_per_pulse
        return (self.values["pulse_divider_level"] + math.floor(pulses / period + 1e-9)) & 1

    def _can_run(self) -> bool:
        return self.mode.serial and self.enabled and not self.protected and self.calibrated \
            and self._calibrating_until < 0

    def _go_home(self, values: Mapping[str, int], answered: bool) -> int:
        v = self.values  # (the drive can run: :meth:`_refusal`)
        if values.get("go_home_mode"):  # coordinate homing (V1.0.9): straight to axis 0 at HmSpeed, no search
            self._start(_Motion("move", Command.GO_HOME, answered, goal=self._clamp_value(max(1, v["home_speed"])),
                                acc=0, target=self.enc_zero))
            return int(_RUN.STARTED)
        if v["home_mode"] == st.HomeMode.SINGLE_LAP:  # V1.0.9: the 0_Mode return, run by go home (S1-S7)
            self._zero_return(Command.GO_HOME, answered)
            return int(_RUN.STARTED)
        home = -1 if v["home_direction"] == st.MotorDirection.CW else 1
        job = _Motion("home", Command.GO_HOME, answered, goal=self._clamp_value(max(1, v["home_speed"])), acc=0)
        self.home_status = int(st.GoBackToZeroStatus.GOING)
        if v["home_mode"] == st.HomeMode.NO_LIMIT:
            job.phase, job.direction = "seek", home
        elif self._home_switch():
            job.phase, job.direction = "leave", -home
        else:
            job.phase, job.direction = "seek", home
        self._start(job)
        return int(_RUN.STARTED)

    def _run_command(self, values: Mapping[str, int], answered: bool) -> int:
        code = self._code_of(values)
        v = self.values
        prefix = _PREFIX[code]
        acc = v[f"{prefix}_acc"]
        speed = v[f"{prefix}_speed"]
        if speed == 0:  # a stop: decelerating with acc, at once with acc 0 (always accepted)
            return self._stop(acc, code, answered)
        goal = self._clamp_value(speed)
        if code == Command.SPEED_MODE:
            run_time = values.get("speed_mode_run_time", 0)  # (a frame without it: 0, untimed)
            self._start(_Motion("speed", code, answered, goal=goal, acc=acc,
                                direction=1 if v["speed_mode_direction"] == st.RunDirection.CCW else -1,
                                until=self.time + run_time * RUN_TIME_UNIT if run_time else math.inf))
            return int(_RUN.STARTED)
        if code == Command.POSITION_MODE1_RELATIVE_PULSES:
            sign = 1 if v["position_mode1_direction"] == st.RunDirection.CCW else -1
            target = self._base() + sign * v["position_mode1_pulses"] * self.rad_per_pulse
        elif code == Command.POSITION_MODE2_ABSOLUTE_PULSES:
            target = self.pulse_zero + v["position_mode2_abs_pulses"] * self.rad_per_pulse
        elif code == Command.POSITION_MODE3_RELATIVE_AXIS:
            target = self._base() + v["position_mode3_rel_axis"] * TAU / COUNTS
        else:
            target = self.enc_zero + v["position_mode4_abs_axis"] * TAU / COUNTS
        self._start(_Motion("move", code, answered, goal=goal, acc=acc, target=target))
        return int(_RUN.STARTED)

    def _code_of(self, values: Mapping[str, int]) -> int:
        for name in values:
            for code, prefix in _PREFIX.items():
                if name.startswith(prefix):
                    return code
        raise ValueError(f"no run command among {sorted(values)}")

    def _base(self) -> float:
        """Where a relative move starts: the running move's target, else the reference."""
        m = self.motion
        return m.target if m is not None and m.kind == "move" and not m.stopping else self.r

    def _refuse(self) -> int:
        self.run_state = st.step(self.run_state, st.RunEvent.REJECT).state
        return int(_RUN.FAIL)

    def _stop(self, acc: int, code: int, answered: bool) -> int:
        """A stop command (speed 0) of run command ``code``: it stops whatever runs; its completion carries
        ``code``."""
        self.sync_held = None  # a stop also drops a run command held for 0x4B
        m = self.motion
        if m is not None:
            self._abandoned(m)  # stopped before it homed / returned to zero
        if acc == 0 or m is None or self.speed == 0:
            tr = st.step(self.run_state, st.RunEvent.STOP if m is None and acc else st.RunEvent.STOP_NOW)
            self.motion = None
            self.speed = 0
            self.v_ref = 0.0
            self.run_state = tr.state
            if tr.completion is not None:
                self._complete(code, int(tr.completion), answered)
            return int(_RUN.STARTED)
        self.run_state = st.step(self.run_state, st.RunEvent.STOP).state
        m.stopping = True
        m.acc = acc
        m.function, m.answered = code, answered
        return int(_RUN.STARTED)

    def _start(self, job: _Motion) -> None:
        """A new job replaces the running one (no completion for the replaced, state.py)."""
        self.run_state = st.step(self.run_state, st.RunEvent.START).state
        if self.motion is not None and self.motion.kind != job.kind:
            self._abandoned(self.motion)  # replaced before it homed / returned to zero
        if self.motion is None or self.speed == 0:
            self._ramp_t = 0.0
        self.motion = job

    def _end(self, event: st.RunEvent, *, quiet: bool = False) -> None:
        """The motion ends (arrival, end limit, e-stop, protection): state machine and completion."""
        m = self.motion
        tr = st.step(self.run_state, event)
        self.run_state = tr.state
        self.motion = None
        if m is not None:  # 0x3B (V1.0.7): homed / returned to zero (a stop that ran out is no arrival)
            if event is st.RunEvent.ARRIVED and m.kind == "home":
                self.home_status = int(st.GoBackToZeroStatus.SUCCESS)
            elif event is st.RunEvent.ARRIVED and m.kind == "zero" and not m.stopping:
                self.zero_status = int(st.GoBackToZeroStatus.SUCCESS)
            else:
                self._abandoned(m)
        self.speed = 0
        self.v_ref = 0.0
        if m is not None and tr.completion is not None and not quiet:
            self._complete(m.function, int(tr.completion), m.answered)

    def _abandoned(self, m: _Motion) -> None:
        """0x3B: a go home (status2) or a single-turn zero return (status1) ended before it arrived: 2, failed."""
        if m.kind == "home":
            self.home_status = int(st.GoBackToZeroStatus.FAIL)
        elif m.kind == "zero":
            self.zero_status = int(st.GoBackToZeroStatus.FAIL)

    def _complete(self, function: int, status: int, answered: bool) -> None:
        self.completions.append(Completion(self.time, int(function), status, answered))

    def _hold(self) -> None:
        self.r = self.q
        self.v_ref = 0.0
        self._integral = 0.0
        self._stall_since = -1.0
        self._perr_since = -1.0

    def _clamp_value(self, value: int) -> int:
        """A speed value limited to the work mode's maximum speed (6.1)."""
        top = st.speed_value(self.mode.max_speed, self.microsteps)
        return max(0, min(value, max(top, 1)))

    def _zero_return(self, function: int = Command.SET_ZERO_MODE, answered: bool = False) -> None:
        """The single-turn zero return: from the encoder's angle, less than one turn to the 0_Mode zero (DirMode: in
        0_Dir; NearMode: the shorter way), at 0_Speed; none within :data:`AT_ZERO` of it. At power-on and on an
        En pulse (no frame), or run by go home in hm_mode 2 (``function`` 0x91: its completion frame)."""
        v = self.values
        assert self.zero_point is not None
        here = (self.q % TAU) * COUNTS / TAU  # the encoder's angle in the turn [counts, not floored]
        if v["zero_mode"] == st.ZeroMode.DIR_MODE:
            ccw = v["zero_mode_direction"] == st.MotorDirection.CCW
            delta = (self.zero_point - here) % COUNTS if ccw else -((here - self.zero_point) % COUNTS)
        else:
            delta = (self.zero_point - here + COUNTS / 2) % COUNTS - COUNTS / 2
        if min(abs(delta), COUNTS - abs(delta)) < AT_ZERO:
            delta = 0.0  # already there: no lap
        self.zero_status = int(st.GoBackToZeroStatus.GOING)
        rpm = ZERO_MODE_RPM[min(max(v["zero_mode_speed"], 0), 4)]
        self.enabled = True
        self._start(_Motion("zero", function, answered,
                            goal=self._clamp_value(st.speed_value(rpm, self.microsteps)),
                            acc=0, target=self.q + delta * TAU / COUNTS))

    # -- status ---------------------------------------------------------------------------------------
    def counts(self) -> int:
        """Encoder axis [counts], floor-quantised."""
        return math.floor((self.q - self.enc_zero) * COUNTS / TAU + 1e-9)

    def turn_counts(self) -> int:
        """The absolute encoder's angle within the turn [counts]: where 0_Mode's zero is kept (0x92 and homing
        move the axis zero, not this)."""
        return math.floor((self.q % TAU) * COUNTS / TAU + 1e-9) % COUNTS

    def _sensed_counts(self) -> int:
        """The encoder axis [counts] as a read reports it (:mod:`joints.sim.sensors`)."""
        sensor = self.sensor
        if sensor.model.ideal:
            return self.counts()
        q = sensor.position(self.time, self.q, self.qd)
        return math.floor((q - self.enc_zero) * COUNTS / TAU + 1e-9)

    def _sensed_speed(self) -> float:
        """The drive's speed estimate [rad/s] (:mod:`joints.sim.sensors`)."""
        sensor = self.sensor
        return self.qd if sensor.model.ideal else sensor.velocity(self.q, self.qd)

    def _switches(self) -> tuple[bool, bool]:
        low, high = self.end_stops
        # (IN_1 an output reads no switch; remapped, the left limit is on En: 0x9E)
        left = low is not None and self.q <= low and (not self._in1_output() or bool(self.values["limit_port_remap"]))
        right = high is not None and self.q >= high and (
            self.profile.limit_inputs >= 2 or bool(self.values["limit_port_remap"]))
        return left, right

    def _home_switch(self) -> bool:
        return self._switches()[0]

    def _in1_output(self) -> bool:
        """IN_1 made an output (0x9F, V1.0.9): it reads the level written to it, not a switch."""
        return bool(self.values["in1_port_mode"])

    def io_status(self) -> int:
        """0x34: IN_1 / IN_2 at their levels (the effective level while triggered), OUT_1 on the 57D."""
        left, right = self._switches()
        level = self.values["home_trigger_level"]
        bits = self.in1_level if self._in1_output() else level if left else 1 - level
        if self.profile.limit_inputs >= 2 or self.values["limit_port_remap"]:
            bits |= (level if right else 1 - level) << 1
        if 1 in self.outputs:  # written by the host (0x36, V1.0.6)
            bits |= self.outputs[1] << 2
        elif self.profile.limit_inputs >= 2:  # OUT_1 stall indication: 0 protected, 1 unprotected (57D only)
            bits |= (0 if self.protected else 1) << 2
        divider = self.divider_level()  # OUT_2 as the pulse divider output (0x99, V1.0.9, 57D)
        return bits | (self.outputs.get(2, 0) if divider is None else divider) << 3

    def motor_status(self) -> st.MotorStatus:
        if self._calibrating_until >= 0:
            return st.MotorStatus.CALIBRATING
        m = self.motion
        if m is None:
            return st.MotorStatus.STOP
        if m.kind == "home" or (m.kind == "zero" and m.function == Command.GO_HOME):
            return st.MotorStatus.HOMING
        if m.arrived >= 0:
            return st.MotorStatus.SPEED_DOWN  # settling on the target
        if self.speed == self.ramp_goal == 0:
            return st.MotorStatus.SPEED_UP  # about to start
        return st.motor_status(self.speed, self.ramp_goal)

    # -- physics side ----------------------------------------------------------------------------------
    def step(self, t: float, dt: float, q: float, qd: float) -> float:
        """Run the drive for the substep ending at ``t``; return the motor torque [N*m]."""
        self.time = t
        self.q, self.qd = q, qd
        if self._power_on:
            self._powered(q)
        if self._reboot_at is not None and t >= self._reboot_at:
            self.power_cycle()
            self._powered(q)
        if self._calibrating_until >= 0 and t >= self._calibrating_until:
            self._calibrating_until = -1.0
            self.calibrated = True
            self._hold()
            self._complete(Command.CALIBRATE_ENCODER, int(st.CalibrationStatus.SUCCESS), self._calibrating_answered)
        for code, (names, period, due) in list(self.timed.items()):
            if t >= due - 1e-12:  # 0x01 timed return: sample now, the front sends it
                self.returns.append(TimedReturn(t, code, tuple(self.read_many(names))))
                self.timed[code] = (names, period, max(due + period, t))
        hb = self.values.get("heartbeat_protection_time", 0)
        if hb and self.motion is not None and t - self._last_frame > hb * 1e-3:
            self.heartbeat_trips += 1  # the host went silent: stop urgently (V1.0.9 5.2.16)
            self.heartbeat_tripped_at = t
            self._end(st.RunEvent.EMERGENCY_STOP)
            self._hold()
        if not self.enabled or self.protected:
            self.r = q  # released: the reference follows the shaft (enable holds where it is)
            self.v_ref = 0.0
            self._integral = 0.0
            return 0.0
        v_prev = self.v_ref
        if self.motion is not None:
            self._generate(dt)
        torque = self._control(dt, (self.v_ref - v_prev) / dt)
        self._protect(dt)
        return torque

    def _rad_s(self, value: int) -> float:
        return min(st.effective_rpm(value, self.microsteps), float(self.mode.max_speed)) * RPM

    def _ramp(self, goal: int, acc: int, dt: float) -> None:
        """Move the speed value toward ``goal`` by the 6.1 law."""
        self.ramp_goal = goal
        if self.speed == goal:
            self._ramp_t = 0.0
            return
        if acc == 0:
            self.speed = goal
            return
        interval = st.ramp_interval(acc)
        self._ramp_t += dt
        n = math.floor(self._ramp_t / interval + 1e-9)
        if n <= 0:
            return
        self._ramp_t -= n * interval
        self.speed = min(self.speed + n, goal) if goal > self.speed else max(self.speed - n, goal)

    def _generate(self, dt: float) -> None:
        m = self.motion
        assert m is not None
        if m.kind == "speed":
            self._speed_job(m, dt)
        elif m.kind == "home":
            self._home_job(m, dt)
        else:
            self._move_job(m, dt)
        if self.motion is not None:
            self._end_limits()

    def _speed_job(self, m: _Motion, dt: float) -> None:
        if not m.stopping and self.time >= m.until - 1e-9:  # the run time is over: a stop with its own acc
            self.run_state = st.step(self.run_state, st.RunEvent.STOP).state
            m.stopping = True
        if m.stopping or (self.speed and m.direction != self.moving_dir):
            self._ramp(0, m.acc, dt)
        else:
            self.moving_dir = m.direction
            self._ramp(m.goal, m.acc, dt)
        self.v_ref = self.moving_dir * self._rad_s(self.speed)
        self.r += self.v_ref * dt
        lead = self.r - self.q
        if abs(lead) > SPEED_MODE_LEAD:  # the rotor cannot follow: the reference waits for it
            self.r = self.q + math.copysign(SPEED_MODE_LEAD, lead)
        if m.stopping and self.speed == 0:
            self._end(st.RunEvent.ARRIVED)

    def _move_job(self, m: _Motion, dt: float) -> None:
        if m.stopping:
            self._ramp(0, m.acc, dt)
            self.v_ref = self.moving_dir * self._rad_s(self.speed)
            self.r += self.v_ref * dt
            if self.speed == 0:
                self._end(st.RunEvent.ARRIVED)
            return
        if m.arrived < 0:
            if not self._advance(m, dt):
                return
            m.arrived = self.time
        if self._settling(m):
            return  # the reference is there; the shaft settles into the window
        if m.kind == "zero" and m.function != Command.GO_HOME:  # at power-on / by En: no frame
            self.zero_status = int(st.GoBackToZeroStatus.SUCCESS)
            self.motion = None
            self.run_state = st.RunState.COMPLETE
            return
        if m.kind == "zero":  # single lap to zero (hm_mode 2): "the current position is reset to zero" (S6)
            self.enc_zero = self.q
            self.pulse_zero = self.q
        self._end(st.RunEvent.ARRIVED)

    def _settling(self, m: _Motion) -> bool:
        """Whether a move whose reference arrived still waits for the shaft before it completes."""
        if not self.mode.closed_loop:
            return False
        error = abs(self.r - self.q)
        if self.time - m.arrived < SETTLE_TIMEOUT and (error > IN_POSITION or abs(self.qd) > IN_POSITION_SPEED):
            return True
        v = self.values  # 0x95 (V1.0.8): never complete outside the threshold, not even after the settle timeout
        return (MKS_POSITION_THRESHOLD in self.firmware.features and m.kind == "move"
                and bool(v["position_threshold_enable"])
                and error * POSITION_THRESHOLD_PER_TURN / TAU >= v["position_threshold"])

    def _advance(self, m: _Motion, dt: float) -> bool:
        """One substep of a move toward ``m.target``; True when the reference arrived (exactly)."""
        remaining = m.target - self.r
        way = 1 if remaining >= 0 else -1
        if self.speed and way != self.moving_dir:  # the target moved behind us: stop first
            self._ramp(0, m.acc, dt)
        elif m.acc == 0:
            self.moving_dir = way
            self.speed = self.ramp_goal = m.goal
        else:
            self.moving_dir = way
            rad_s = self._rad_s(self.speed)
            brake = rad_s * self.speed * st.ramp_interval(m.acc) * 0.5 + rad_s * dt
            self._ramp(0 if abs(remaining) <= brake else m.goal, m.acc, dt)
            if self.speed == 0:
                self.speed = 1  # creep the last bit at the smallest speed step
        step = self._rad_s(self.speed) * dt
        if self.moving_dir == way and step >= abs(remaining):
            self.r = m.target
            self.v_ref = 0.0
            self.speed = self.ramp_goal = 0
            return True
        self.v_ref = self.moving_dir * self._rad_s(self.speed)
        self.r += self.v_ref * dt
        return False

    def _home_job(self, m: _Motion, dt: float) -> None:
        if m.phase == "back":
            if self._advance(m, dt):
                self._homed(m)
            return
        self.speed = self.ramp_goal = m.goal
        self.moving_dir = m.direction
        self.v_ref = m.direction * self._rad_s(self.speed)
        self.r += self.v_ref * dt
        values = self.values
        if values["home_mode"] == st.HomeMode.NO_LIMIT:
            if abs(self.r - self.q) > HOME_STALL:  # blocked: back off retValue from here
                back = values["home_reverse_angle"] * TAU / COUNTS
                self.r = self.q
                self.speed = 0
                m.phase, m.target = "back", self.q - m.direction * back
            return
        switch = self._home_switch()
        if m.phase == "leave" and not switch:
            m.phase, m.direction = "seek", -m.direction
        elif m.phase == "seek" and switch:
            self.r = self.q
            self._homed(m)

    def _homed(self, m: _Motion) -> None:
        self.enc_zero = self.q
        self.pulse_zero = self.q
        self.r = self.q
        self._end(st.RunEvent.ARRIVED)
        if self.values["end_limit"]:
            self.enabled = False  # 5.3 note 2: with EndLimit on the shaft is unlocked after go home

    def _end_limits(self) -> None:
        m = self.motion
        if m is None or m.kind in ("home", "zero") or not self.values["end_limit"] or self.speed == 0:
            return
        left, right = self._switches()
        if (left and self.moving_dir < 0) or (right and self.moving_dir > 0):
            self._end(st.RunEvent.END_LIMIT)
            self._hold()

    # -- the motor ----------------------------------------------------------------------------------
    def available_torque(self) -> float:
        current = self.current
        m = self.motion
        if m is not None and m.kind == "home" and self.values["home_mode"] == st.HomeMode.NO_LIMIT:
            current = self.values["home_current"] * 1e-3
        elif not self.mode.foc and m is None:
            current *= st.holding_current_percent(self.values["holding_current"]) / 100.0
        return self.profile.available_torque(self.qd, current)

    def _control(self, dt: float, accel: float) -> float:
        limit = self.available_torque()
        J = self.inertia
        q, qd = self.q, self.qd
        if self.mode.closed_loop:
            w = SERVO_BANDWIDTH
            kp, kd = J * w * w, 2.0 * SERVO_DAMPING * J * w
            ki = kp * w / 10.0
            err = self.r - q
            drive = kp * err + kd * self.v_ref + ki * self._integral + J * accel
            qd_new = (J * qd / dt + drive) / (J / dt + kp * dt + kd)
            torque = J * (qd_new - qd) / dt
            if -limit < torque < limit:
                self._integral += err * dt
                return torque
            return limit if torque > 0 else -limit
        # OPEN: the field sits on the microstep the reference is at and pulls with T sin(50 x angle)
        field = self.pulse_zero + round((self.r - self.pulse_zero) / self.rad_per_pulse) * self.rad_per_pulse
        angle = POLE_PAIRS * (field - q)
        pull = limit * math.sin(angle)
        k = POLE_PAIRS * limit * max(math.cos(angle), 0.0)
        c = self.profile.back_emf_constant ** 2 / self.profile.phase_resistance  # electrical damping
        qd_new = (J * qd / dt + pull + c * self.v_ref) / (J / dt + k * dt + c)
        torque = J * (qd_new - qd) / dt
        return max(-limit, min(limit, torque))

    def _protect(self, dt: float) -> None:
        """The locked-rotor protection (0x88) and the position-error protection (0x9D, V1.0.6): each watches
        the position error on its own (closed modes only: OPEN has no position feedback)."""
        error = abs(self.r - self.q)
        v = self.values
        if v["locked_rotor_protection"] and self.mode.closed_loop and error > self.profile.stall_error:
            if self._stall_since < 0:
                self._stall_since = self.time
            elif self.time - self._stall_since >= self.profile.stall_time - 1e-9:
                self._protection("locked-rotor")
                return
        else:
            self._stall_since = -1.0
        if (v["position_error_protection"] and self.mode.closed_loop
                and error * POSITION_ERROR_PER_TURN / TAU > v["position_error_count"]):
            if self._perr_since < 0:
                self._perr_since = self.time
            if self.time - self._perr_since >= v["position_error_time"] * POSITION_ERROR_TICK - 1e-9:
                self._protection("position-error")
        else:
            self._perr_since = -1.0

    def _protection(self, cause: str) -> None:
        self.protected = True
        self.protection_cause = cause
        self._end(st.RunEvent.PROTECTION)
        self._hold()
        self._perr_since = -1.0

    def take_completions(self, now: float) -> list[Completion]:
        """Completions due by ``now`` (the front turns them into frames)."""
        out: list[Completion] = []
        while self.completions and self.completions[0].time <= now + 1e-12:
            out.append(self.completions.popleft())
        return out

