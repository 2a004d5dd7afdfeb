"""joints: drive real robot joints over their buses, and simulate the same joints in MuJoCo.

>>> import joints
>>> with joints.open("robot.toml") as rig:        # doctest: +SKIP
...     rig.joints["shoulder"].enable()
"""

from __future__ import annotations

from joints.bench import check_rate, cycle_times
from joints.compiled_path import CompiledPath, CompiledRigs
from joints.configtypes import Limits, Motion
from joints.errors import (
    ConfigError,
    ConfirmationRequired,
    DeviceFault,
    JointsError,
    ProtocolError,
    ReplyTimeout,
)
from joints.joint import Joint, JointState
from joints.rig import Rig, open, sleep_together

__version__ = "0.1.0"

__all__ = [
    "CompiledPath",
    "CompiledRigs",
    "ConfigError",
    "ConfirmationRequired",
    "DeviceFault",
    "Joint",
    "JointState",
    "JointsError",
    "Limits",
    "Motion",
    "ProtocolError",
    "ReplyTimeout",
    "Rig",
    "__version__",
    "check_rate",
    "cycle_times",
    "open",
    "sleep_together",
]
