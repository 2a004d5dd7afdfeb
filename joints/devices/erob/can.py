"""eRob over the ZeroErr CAN custom protocol: address map, error-reply codes, module information.

Source: eRunner user manual v1.7 (zh): 7.5.1 (parameter and variable addresses), 7.5.2 (command
addresses), 7.5.3 (module information), appendix 1 (error codes of the error replies), and the
examples of chapter 4 and 7.4. The frames themselves are :mod:`joints.codecs.erob_can`.

Rule: pure data and pure functions, shared by the driver and the twin. :data:`EROB_CAN` maps every
CAN index to a parameter of :data:`~joints.devices.erob.params.EROB_PARAMS` by the SAME name as
the eRob Modbus table wherever the quantity is the same (``actual_position`` is Modbus 0x0066 and
CAN 0x0002); quantities only CAN reaches are in ``OTHER_PROTOCOLS`` there. A :class:`CanIndex`
key compares by (index, subindex) only; its other fields say how the protocol reaches the
parameter:

* ``reach``: a value (Read/Write messages), or a command of 7.5.2 without/with parameter;
* ``scale``: parameter value = CAN value x scale, where CAN counts in other units than the
  parameter (which carries the Modbus unit): the times 0x0058, 0x0093, 0x010A are in ms over CAN
  and in 0.05 ms over Modbus, so ``scale`` is 20 and ``unit`` is "ms";
* ``access``: where CAN reaches the parameter with less access than Modbus (the current limits
  0x0033-0x0035 are read-only over CAN);
* ``definition``/``source``/``note``: the manual's name, where it is printed, and deviations.

Use :meth:`CanMap.to_wire`/:meth:`CanMap.from_wire` to convert between parameter values and the
signed 32-bit values of the frames (scale, range check, unsigned 32-bit quantities).

Choices where the manual is silent or wrong (ERRATA ids from tests/data/ERRATA.md):

* 0x000D U-phase voltage is printed with unit mA: it is mV like V/W (DOC-EROB-CAN-3).
* 0x01FD/0x01FE (analog set-point type/value) are used by every speed/torque example but missing
  from table 7.5.1 (DOC-EROB-CAN-2): mapped as ``analog_quantity_type``/``analog_quantity_value``.
  0x01FE is the target speed (count/s) in speed mode and the target current (mA) in torque mode,
  so it is neither Modbus ``target_speed`` nor ``target_current``: a driver writes it for both.
* The value lists of 0x0020 (motion status), 0x010C (target-reached status) lost their numbers in
  the OCR; they are the Modbus states (0x0061, 0x0063), which name the same states in order.
* 0x0112 (control source), 0x020D (torque sensor value) and 0x0232/5 (module configuration) have
  their definition cell lost or garbled in the OCR; the names come from the examples ("设置控制源为
  不使用") and the description/bit fields.
* 0x00FF "COM 号" (the RS485 COM port's id) is taken to be the Modbus slave address.
* 0x004E lists a fourth operation mode (4, garbled in the OCR) and 0x0112 a control source 16
  that the Modbus table does not have; the parameters keep the Modbus ranges (1..3, 0..1), so
  these values are refused rather than sent blind.
* 0x0114 (load-side encoder reset, "write 1") is in the parameter table: over the wire it is a
  Write of 1, not a 7.5.2 command; it is the Modbus ``reset_output_encoder`` (0x00F9).
* Error replies carry the codes of appendix 1, the same firmware codes as
  :mod:`joints.devices.erob.faults` (#1-#5, #8, #9 were there; #6 0x0032 and #7 0x0033, the CAN
  command-shape errors, were added). The drive error code read from 0x001F refers to the actuator
  user manual's appendix 2, which is not in our manual set: :func:`joints.devices.erob.faults.describe`.
* Module information (0x0232) needs firmware X5061715X or later (note under 7.5.1). The manual
  does not say how versions compare; :func:`module_info_supported` reads 'X' as any digit and
  compares the seven digits between them, and says "unknown" (None) for other formats.
* The hardware version string's second separator is lost in the OCR of 7.5.3 ("1005 1 1"); both
  are taken to be "_" like the first.
"""

from __future__ import annotations

import enum
import re
from collections.abc import Mapping
from dataclasses import dataclass, field

from joints.devices.erob.faults import FaultInfo, describe
from joints.devices.erob.params import EROB_PARAMS
from joints.devices.params import Access, ParamMap
from joints.errors import CommandError

__all__ = [
    "EROB_CAN",
    "ERROR_REPLY_TEXT",
    "MODULE_INFO_MIN_FIRMWARE",
    "NO_ERROR",
    "CanIndex",
    "CanMap",
    "ModuleConfig",
    "ModuleInfo",
    "Reach",
    "describe_error_reply",
    "module_info_supported",
]


class Reach(enum.Enum):
    """How the protocol reaches a parameter."""

    VALUE = "value"  #: Read / Write (7.1, 7.2)
    COMMAND = "command"  #: Command without parameter (7.3, table 7-9)
    COMMAND_WITH_PARAMETER = "command with parameter"  #: Command with a 4-byte parameter (table 7-10)


@dataclass(frozen=True, slots=True)
class CanIndex:
    """Where a parameter is over the CAN custom protocol; equal keys = same index and subindex."""

    index: int
    subindex: int | None = None
    reach: Reach = field(default=Reach.VALUE, compare=False)
    scale: int = field(default=1, compare=False)  #: parameter value = CAN value * scale
    unit: str | None = field(default=None, compare=False)  #: CAN's unit where it differs from the parameter's
    access: Access | None = field(default=None, compare=False)  #: CAN's access where it differs
    definition: str = field(default="", compare=False)  #: the manual's name (zh)
    source: str = field(default="7.5.1", compare=False)  #: where the manual defines it
    note: str = field(default="", compare=False)  #: deviations, errata

    def __str__(self) -> str:
        return f"0x{self.index:04X}" + ("" if self.subindex is None else f"/{self.subindex}")


_INT32_MAX = 0x7FFFFFFF


class CanMap(ParamMap[CanIndex]):
    """The CAN custom-protocol map of the eRob parameters, with value conversion."""

    def access(self, name: str) -> Access:
        """The access this protocol gives to ``name`` (the key's, else the parameter's)."""
        key = self.key(name)
        return key.access if key.access is not None else self.param(name).access

    def unit(self, name: str) -> str:
        """The unit of the CAN value of ``name``."""
        key = self.key(name)
        return key.unit if key.unit is not None else self.param(name).unit

    def to_wire(self, name: str, value: object) -> int:
        """The signed 32-bit frame value for parameter ``name`` = ``value`` (range-checked).

        Raises :class:`~joints.errors.CommandError` for a value out of the parameter's range or
        one that the CAN unit cannot carry exactly (scaled parameters).
        """
        param, key = self.param(name), self.key(name)
        v = param.check(value)
        if key.scale != 1:
            q, r = divmod(v, key.scale)
            if r:
                raise CommandError(f"{name}: {v} {param.unit} is not a whole number of {self.unit(name)} "
                                   f"(CAN {key} carries {self.unit(name)} = {key.scale} {param.unit})")
            v = q
        return v - (1 << 32) if v > _INT32_MAX else v

    def from_wire(self, name: str, raw: int) -> int:
        """The parameter value of ``name`` from a frame's signed 32-bit value."""
        param, key = self.param(name), self.key(name)
        if param.type == "uint32":
            raw &= 0xFFFFFFFF
        return raw * key.scale

    def at(self, index: int, subindex: int | None = None) -> str:
        """The parameter name at a CAN index/subindex (RegisterError if none)."""
        return self.name_of(CanIndex(index, subindex))


# --- the address table ----------------------------------------------------------------------

_R, _RW, _CMD = Access.R, Access.RW, Access.COMMAND
_EX = "examples 4.2, 4.3, 7.4.4, 7.4.5 (not in 7.5.1, ERRATA DOC-EROB-CAN-2)"


def _k(index: int, subindex: int | None, definition: str, *, reach: Reach = Reach.VALUE, scale: int = 1,
       unit: str | None = None, access: Access | None = None, source: str = "7.5.1", note: str = "") -> CanIndex:
    return CanIndex(index, subindex, reach, scale, unit, access, definition, source, note)


_KEYS: dict[str, CanIndex] = {
    # ---- 7.5.1 parameters and variables ----------------------------------------------------
    "hardware_version": _k(0x0001, 3, "硬件版本"),
    "firmware_version": _k(0x0001, 4, "固件版本"),
    "actual_position": _k(0x0002, None, "实际位置"),
    "current_speed": _k(0x0005, 1, "实际速度",
                        note="measured output speed: the Modbus 'Current Speed' (0x006E)"),
    "motor_current": _k(0x0008, None, "实际电机电流"),
    "u_phase_current": _k(0x0009, None, "U相电流"),
    "v_phase_current": _k(0x000A, None, "V相电流"),
    "u_phase_voltage": _k(0x000D, None, "U相电压", note="unit printed as mA, read mV (ERRATA DOC-EROB-CAN-3)"),
    "v_phase_voltage": _k(0x000E, None, "V相电压"),
    "w_phase_voltage": _k(0x000F, None, "W相电压"),
    "error_code": _k(0x001F, None, "错误代码",
                     note="0 = ready; other codes: actuator user manual appendix 2 (not in our manual set)"),
    "motion_status": _k(0x0020, None, "运行状态",
                        note="value list lost its numbers in the OCR; the Modbus states (0x0061)"),
    "digital_inputs": _k(0x0022, None, "数字量输入"),
    "analog_input": _k(0x0023, None, "模拟量输入"),
    "bus_voltage": _k(0x0024, None, "直流母线电压"),
    "part_of_power_temperature": _k(0x0026, None, "功率温度"),
    "continuous_current": _k(0x0033, None, "持续电流", access=_R, note="read-only over CAN"),
    "peak_current": _k(0x0034, None, "峰值电流", access=_R, note="read-only over CAN"),
    "peak_current_time": _k(0x0035, None, "峰值电流持续时间", access=_R, note="read-only over CAN"),
    "can_address": _k(0x0043, None, "CAN地址", note="node id change: persistent, needs confirmation"),
    "can_baud_rate": _k(0x0044, None, "CAN波特率", note="fixed at 1 Mbit/s"),
    "operation_mode": _k(0x004E, None, "运行模式",
                         note="CAN also lists 4 (name garbled in the OCR); the parameter keeps 1..3"),
    "max_speed": _k(0x0050, None, "最大速度"),
    "min_position_limit_value": _k(0x0052, None, "位置限制(最小值)"),
    "max_position_limit_value": _k(0x0053, None, "位置限制(最大值)"),
    "max_position_error": _k(0x0054, None, "允许最大位置误差"),
    "max_speed_error": _k(0x0055, None, "允许最大速度误差"),
    "struck_current": _k(0x0056, None, "堵转电流",
                         note="factory setting 120% (eRob70/80/90) or 110% (eRob110/142) of the continuous current"),
    "struck_speed": _k(0x0057, None, "堵转速度"),
    "struck_time": _k(0x0058, None, "堵转时间", scale=20, unit="ms",
                      note="ms over CAN, 0.05 ms over Modbus (0x00C9)"),
    "max_phase_current": _k(0x0062, None, "最大单相电流(关断)"),
    "max_motor_current": _k(0x0063, None, "最大电机电流(关断)"),
    "position_loop_gain": _k(0x0064, None, "位置环增益"),
    "speed_loop_gain": _k(0x0066, None, "速度环增益"),
    "speed_loop_integral": _k(0x0067, None, "速度环积分"),
    "target_absolute_position": _k(0x0086, None, "绝对目标位置",
                                   note="an absolute move needs target_relative_position = 0 first (7.5.1, 7.4.1)"),
    "target_relative_position": _k(0x0087, None, "相对位置"),
    "profile_acceleration": _k(0x0088, None, "轮廓加速度"),
    "profile_deceleration": _k(0x0089, None, "轮廓减速度"),
    "profile_speed": _k(0x008A, None, "轮廓速度",
                        note="in continuous motion its sign is the direction (7.4.3, figure 4-17)"),
    "jerk_setting": _k(0x008B, None, "加加速度设定", unit="", note="printed unit 'us': the value is a time code"),
    "emergency_stop_deceleration": _k(0x008C, None, "急停速度",
                                      note="printed name 'emergency stop speed', unit count/s^2: a deceleration"),
    "motion_mode": _k(0x008D, None, "运动模式"),
    "dwell_time": _k(0x0093, None, "停止时间", scale=20, unit="ms",
                     note="ms over CAN, 0.05 ms over Modbus (0x004D)"),
    "motor_angle": _k(0x009C, None, "电机转角"),
    "apply_acceleration_limits_to_all_motions": _k(0x009E, None, "应用加减速限制所有运动"),
    "load_angle": _k(0x009F, None, "负载转角"),
    "phase_current_sum_error": _k(0x00FD, None, "三项电流和误差", note="'三项' as printed (three-phase)"),
    "w_phase_current": _k(0x00FE, None, "W相电流"),
    "modbus_address": _k(0x00FF, None, "COM号", note="'RS485 COM port id', taken to be the Modbus slave address"),
    "position_reaches_set_precision": _k(0x0109, None, "定位完成阈值"),
    "time_setting_of_achieving_position": _k(0x010A, None, "定位完成判定时间", scale=20, unit="ms",
                                             note="ms over CAN, 0.05 ms over Modbus (0x007A)"),
    "status_of_achieving_position": _k(0x010C, None, "目标到达状态",
                                       note="value 2 lost in the OCR; the Modbus states (0x0063)"),
    "control_source": _k(0x0112, None, "控制源",
                         note="definition cell lost in the OCR, name from the examples; CAN also lists 16"),
    "reset_output_encoder": _k(0x0114, None, "重置负载端编码器",
                               note="write 1 after fixing a multi-turn battery alarm; wipes the multi-turn count"),
    "use_bus_to_tune_pid": _k(0x0124, None, "使用总线调节PID"),
    "max_output_torque": _k(0x0129, None, "最大输出力矩"),
    "torque_control_mode_max_speed": _k(0x0204, None, "最大速度限制",
                                        note="writable only while disabled (7.4.5 step 5)"),
    "torque_sensor_value": _k(0x020D, None, "扭矩传感器数值",
                              note="definition cell lost in the OCR; only modules with a torque sensor (-18xT)"),
    "module_serial": _k(0x0232, 1, "模组流水号"),
    "module_model_info": _k(0x0232, 2, "模组型号信息"),
    "module_configuration": _k(0x0232, 5, "模组配置信息", note="definition cell garbled in the OCR ('快')"),
    "hardware_change_id": _k(0x0232, 6, "硬件变更识别"),
    "io_function_id": _k(0x0232, 7, "是否带IO功能的识别号"),
    "module_version": _k(0x0232, 8, "模组版本号"),
    # ---- 7.5.2 commands --------------------------------------------------------------------
    "start_operating": _k(0x0083, None, "开始运动", reach=Reach.COMMAND, source="7.5.2"),
    "stop_operating": _k(0x0084, None, "停止运动", reach=Reach.COMMAND, source="7.5.2",
                         note="decelerates with the profile deceleration"),
    "save_parameters": _k(0x00E8, None, "保存", reach=Reach.COMMAND, source="7.5.2",
                          note="wait 3 s before cutting power"),
    "enable_the_motor": _k(0x0100, None, "电机使能", reach=Reach.COMMAND_WITH_PARAMETER, source="7.5.2"),
    "release_brake": _k(0x014F, None, "释放刹车", reach=Reach.COMMAND, source="7.5.2"),
    # ---- used by the examples only ---------------------------------------------------------
    "analog_quantity_type": _k(0x01FD, None, "模拟量类型", source=_EX),
    "analog_quantity_value": _k(0x01FE, None, "模拟量值", source=_EX),
}

EROB_CAN: CanMap = CanMap("erob-can", EROB_PARAMS, _KEYS)
"""The eRob CAN custom-protocol map (every index of 7.5.1/7.5.2 and the examples)."""


# --- error replies (appendix 1) -------------------------------------------------------------

#: ``error_code`` (0x001F) when the drive has no error: "0: 准备完成" (ready), table 7.5.1.
NO_ERROR = 0


#: The error codes of appendix 1 with the manual's alarm text (zh); English text and hint via
#: :func:`describe_error_reply` (joints.devices.erob.faults).
ERROR_REPLY_TEXT: dict[int, str] = {
    0x0015: "在电机运动期间,参数赋值或命令调用无效",
    0x0016: "在电机使能情况下,参数赋值或命令调用无效",
    0x001F: "上电后换向未完成,无法使能",
    0x0027: "如果电机关闭,无法开始运动",
    0x0030: "尝试使用无效的运动模式值开始运动",
    0x0032: "此命令需要一个参数",
    0x0033: "此命令不需要参数",
    0x0056: "如果继电器尚未激活,则无法启用电机",
    0x014A: "没有使用刹车控制",
}


def describe_error_reply(code: int) -> FaultInfo:
    """Text and hint of an error-reply code (unknown codes get a pointer to the vendor's table)."""
    return describe(code)


# --- module information (7.5.3) -------------------------------------------------------------

#: Index 0x0232 needs this firmware or later (note under table 7.5.1); 'X' is any digit.
MODULE_INFO_MIN_FIRMWARE = "X5061715X"


def module_info_supported(firmware_version: int) -> bool | None:
    """Whether firmware ``firmware_version`` (index 0x0001/4) answers index 0x0232; None if unknown.

    Reads :data:`MODULE_INFO_MIN_FIRMWARE` as nine digits whose first and last are any digit and
    compares the seven between them; a version of another format gives None (try, and take an
    error reply as "not supported").
    """
    text = str(firmware_version)
    if len(text) != 9 or not text.isdigit():
        return None
    return int(text[1:8]) >= int(MODULE_INFO_MIN_FIRMWARE[1:8])


def _nibble(word: int, bit: int) -> int:
    return (word >> bit) & 0xF


def _hex_digits(lo: int, hi: int) -> dict[int, str]:
    return {v: f"{v:X}" for v in range(lo, hi + 1)}


#: parameter value -> outer-diameter number (0x0232/2 bit16-19); 1, 7 and 8 all mean 70
OUTER_DIAMETER: dict[int, int] = {1: 70, 7: 70, 8: 70, 2: 80, 3: 90, 4: 110, 5: 142, 6: 170}
REDUCER_TYPE: dict[int, str] = {1: "F", 2: "H"}  #: 0x0232/5 bit20-23
RATIO: dict[int, int] = {1: 50, 2: 80, 3: 100, 4: 120, 5: 160}  #: 0x0232/2 bit12-15
MOUNTING: dict[int, str] = {1: "I", 2: "T", 3: "BI", 4: "BT"}  #: 0x0232/5 bit24-27
BRAKE: dict[int, str] = {1: "F", 2: "B"}  #: 0x0232/5 bit16-19
ENCODER: dict[int, str] = {1: "S", 2: "M", 3: "HS", 4: "HM"}  #: 0x0232/5 bit0-3 (output encoder)
COMMUNICATION: dict[int, str] = {1: "E", 2: "C"}  #: 0x0232/5 bit8-11
TORQUE_SENSOR: dict[int, str] = {1: "N", 2: "T"}  #: 0x0232/5 bit4-7
MOTOR_VERSION: dict[int, str] = {1: "1", 2: "2"}  #: 0x0232/8 bit0-3
HOUSING_VERSION: dict[int, str] = {1: "A", 2: "B", 3: "C", 4: "D", 5: "E"}  #: 0x0232/8 bit4-7
MECHANICS_VISIBLE: dict[int, str] = _hex_digits(1, 0xE)  #: 0x0232/8 bit8-11
REDUCER_VERSION: dict[int, str] = {1: "A", 2: "B", 3: "C", 4: "c", 5: "D", 6: "d", 7: "E", 8: "e"}  #: bit12-15
DRIVER_VERSION: dict[int, str] = _hex_digits(1, 0xE)  #: 0x0232/8 bit16-19
MECHANICS_HIDDEN: dict[int, str] = {1: "A", 2: "B", 3: "C", 4: "D", 5: "E"}  #: 0x0232/8 bit20-23

_MODEL_RE = re.compile(r"eRob(\d+)([A-Z])(\d+)(BI|BT|I|T)-([A-Z])(HS|HM|S|M)-18([A-Z])([A-Z])")
_VERSION_RE = re.compile(r"MC(.)(.)\.(.)(.)\.(.)(.)")


def _code(table: Mapping[int, object], value: object, what: str) -> int:
    for code, v in table.items():
        if v == value:
            return code
    allowed = ", ".join(repr(v) for v in dict.fromkeys(table.values()))
    raise CommandError(f"eRob module information: {what} {value!r} is not in 7.5.3 (allowed: {allowed})")


def _label(table: Mapping[int, object], value: int) -> str:
    v = table.get(value)
    return "?" if v is None else str(v)


@dataclass(frozen=True, slots=True)
class ModuleConfig:
    """What a module is, in the terms of its model string (7.5.3), e.g. ``eRob70H100I-BM-18EN``."""

    outer_diameter: int = 70  #: 70, 80, 90, 110, 142, 170
    reducer: str = "H"  #: F, H
    ratio: int = 100  #: 50, 80, 100, 120, 160
    mounting: str = "I"  #: I, T, BI, BT
    brake: str = "B"  #: F (without), B (with)
    encoder: str = "M"  #: output encoder S, M, HS, HM
    communication: str = "E"  #: E, C
    torque_sensor: str = "N"  #: N (without), T (with)

    @property
    def model(self) -> str:
        return (f"eRob{self.outer_diameter}{self.reducer}{self.ratio}{self.mounting}-{self.brake}{self.encoder}"
                f"-18{self.communication}{self.torque_sensor}")

    @classmethod
    def from_model(cls, model: str) -> ModuleConfig:
        """Parse a model string (CommandError if it is not one of 7.5.3's)."""
        m = _MODEL_RE.fullmatch(model)
        if m is None:
            raise CommandError(f"eRob module information: {model!r} is not a model string like 'eRob70H100I-BM-18EN'")
        d, red, ratio, mount, brake, enc, comm, torque = m.groups()
        config = cls(int(d), red, int(ratio), mount, brake, enc, comm, torque)
        config.check()
        return config

    def check(self) -> None:
        """CommandError unless every field is a value of 7.5.3's tables."""
        _code(OUTER_DIAMETER, self.outer_diameter, "outer diameter")
        _code(REDUCER_TYPE, self.reducer, "reducer type")
        _code(RATIO, self.ratio, "ratio")
        _code(MOUNTING, self.mounting, "mounting type")
        _code(BRAKE, self.brake, "brake")
        _code(ENCODER, self.encoder, "output encoder")
        _code(COMMUNICATION, self.communication, "communication type")
        _code(TORQUE_SENSOR, self.torque_sensor, "torque sensor")


def version_word(text: str) -> int:
    """0x0232/8 from a module version string such as ``MC2A.BC.DE`` (inverse of :attr:`ModuleInfo.version_text`)."""
    m = _VERSION_RE.fullmatch(text)
    if m is None:
        raise CommandError(f"eRob module information: {text!r} is not a module version like 'MC2A.BC.DE'")
    tables = (MOTOR_VERSION, HOUSING_VERSION, MECHANICS_VISIBLE, REDUCER_VERSION, DRIVER_VERSION, MECHANICS_HIDDEN)
    word = 0
    for i, (table, part) in enumerate(zip(tables, m.groups(), strict=True)):
        word |= _code(table, part, "version digit") << (4 * i)
    return word


@dataclass(frozen=True, slots=True)
class ModuleInfo:
    """Module information as the drive reports it: raw values of 0x0232 (and versions of 0x0001).

    Fields are the parameter values (unsigned); the properties build the strings of 7.5.3. A code
    that 7.5.3 does not list shows as "?" in the strings.
    """

    serial: int  #: 0x0232/1 module_serial
    model_info: int  #: 0x0232/2 module_model_info
    configuration: int  #: 0x0232/5 module_configuration
    hardware_change: int = 0  #: 0x0232/6 hardware_change_id
    io_function: int = 0  #: 0x0232/7 io_function_id
    version: int = 0  #: 0x0232/8 module_version
    hardware_version: int = 0  #: 0x0001/3
    firmware_version: int = 0  #: 0x0001/4

    #: parameter name of each field, in field order
    NAMES = ("module_serial", "module_model_info", "module_configuration", "hardware_change_id",
             "io_function_id", "module_version", "hardware_version", "firmware_version")

    # -- the strings of 7.5.3 --
    @property
    def serial_number(self) -> str:
        """Outer-diameter number (3 digits) + module sequence number (8 digits), e.g. ``07000001111``."""
        d = OUTER_DIAMETER.get(_nibble(self.model_info, 16))
        return ("???" if d is None else f"{d:03d}") + f"{self.serial:08d}"

    @property
    def model(self) -> str:
        """The model string, e.g. ``eRob70H100I-BM-18EN``."""
        mi, cf = self.model_info, self.configuration
        return (f"eRob{_label(OUTER_DIAMETER, _nibble(mi, 16))}{_label(REDUCER_TYPE, _nibble(cf, 20))}"
                f"{_label(RATIO, _nibble(mi, 12))}{_label(MOUNTING, _nibble(cf, 24))}"
                f"-{_label(BRAKE, _nibble(cf, 16))}{_label(ENCODER, _nibble(cf, 0))}"
                f"-18{_label(COMMUNICATION, _nibble(cf, 8))}{_label(TORQUE_SENSOR, _nibble(cf, 4))}")

    @property
    def hardware_version_text(self) -> str:
        """Hardware version + "_" + hardware change id + "_" + IO flag, e.g. ``1005_1_1``."""
        return f"{self.hardware_version}_{self.hardware_change}_{self.io_function}"

    @property
    def version_text(self) -> str:
        """The module version, e.g. ``MC2A.BC.DE``."""
        w = self.version
        return (f"MC{_label(MOTOR_VERSION, _nibble(w, 0))}{_label(HOUSING_VERSION, _nibble(w, 4))}"
                f".{_label(MECHANICS_VISIBLE, _nibble(w, 8))}{_label(REDUCER_VERSION, _nibble(w, 12))}"
                f".{_label(DRIVER_VERSION, _nibble(w, 16))}{_label(MECHANICS_HIDDEN, _nibble(w, 20))}")

    @property
    def config(self) -> ModuleConfig:
        """The configuration (CommandError if a code is not in 7.5.3's tables)."""
        return ModuleConfig.from_model(self.model)

    # -- values by parameter name --
    def values(self) -> dict[str, int]:
        """The parameter values a drive reports, by parameter name (what a twin answers)."""
        return dict(zip(self.NAMES, (self.serial, self.model_info, self.configuration, self.hardware_change,
                                     self.io_function, self.version, self.hardware_version,
                                     self.firmware_version), strict=True))

    @classmethod
    def from_values(cls, values: Mapping[str, int]) -> ModuleInfo:
        """From parameter values by name (what a driver read); versions default to 0 if absent."""
        return cls(*(values.get(n, 0) for n in cls.NAMES))

    @classmethod
    def build(cls, config: ModuleConfig | str, serial: int, *, version: str | int = 0, hardware_version: int = 0,
              firmware_version: int = 0, hardware_change: int = 0, io_function: int = 0, motor_type: int = 0,
              through_hole: int = 0) -> ModuleInfo:
        """The information a module of ``config`` (a :class:`ModuleConfig` or a model string) reports.

        ``motor_type`` (0x0232/2 bit4-7) and ``through_hole`` (0x0232/5 bit12-15) are not part of
        the model string; 7.5.3 gives no values for them.
        """
        if isinstance(config, str):
            config = ModuleConfig.from_model(config)
        config.check()
        model_info = ((_code(OUTER_DIAMETER, config.outer_diameter, "outer diameter") << 16)
                      | (_code(RATIO, config.ratio, "ratio") << 12) | ((motor_type & 0xF) << 4))
        configuration = ((_code(ENCODER, config.encoder, "output encoder"))
                         | (_code(TORQUE_SENSOR, config.torque_sensor, "torque sensor") << 4)
                         | (_code(COMMUNICATION, config.communication, "communication type") << 8)
                         | ((through_hole & 0xF) << 12)
                         | (_code(BRAKE, config.brake, "brake") << 16)
                         | (_code(REDUCER_TYPE, config.reducer, "reducer type") << 20)
                         | (_code(MOUNTING, config.mounting, "mounting type") << 24))
        word = version_word(version) if isinstance(version, str) else version
        return cls(serial, model_info, configuration, hardware_change, io_function, word, hardware_version,
                   firmware_version)
