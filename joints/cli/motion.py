"""``joints move``, ``jog``, ``enable``, ``disable``, ``stop`` and ``clear``: per-mode motion panels.

Rules:

* Every target goes through :class:`~joints.joint.Joint`: the config's limits are enforced and a
  command outside them sends nothing (exit code 2).
* ``move`` and ``jog`` run in the foreground with a progress display until the target is reached
  (or the jog's duration is over, or the timeout passes: exit 1). Done or interrupted, they stop
  and disable what they enabled and put back the watchdog and operating mode they found
  (:attr:`~joints.registry.DeviceFamily.mode_params`). A joint found enabled is left enabled.
* ``--hold`` (and ``enable``, a one-shot that always holds) leaves the joint enabled and holding,
  with the communication watchdog switched off - nothing will feed it once the command ends - and
  says so on stderr. A jog always ends stopped: an MKS axis (no watchdog) is never left running in
  speed mode by a one-shot.
* ``--mode`` picks a protocol's operating mode for this command (CANopen pp/pv/pt/csp/csv/cst/ip;
  the registry's :attr:`~joints.registry.DeviceFamily.modes`): cyclic modes are streamed with
  :meth:`~joints.rig.Rig.cycle`. ``--pulses`` moves an MKS in its pulse modes (1 and 2).
"""

from __future__ import annotations

import argparse
import dataclasses
from typing import TYPE_CHECKING, Any

from joints import registry
from joints.cli.basic import observe, state_dict
from joints.cli.common import (
    UsageError,
    add_config,
    add_json,
    command,
    emit_json,
    joint,
    load_config,
    nonnegative,
    note,
    number,
    open_rig,
    positive,
    warn,
)
from joints.cli.params import read_settings
from joints.cli.ui import Progress, cell
from joints.errors import CommandError, DeviceFault, DeviceRejected, JointsError, MotionTimeout

if TYPE_CHECKING:
    from joints.joint import Joint, JointState
    from joints.rig import Rig

#: s allowed for a stop to come to rest before the joint is disabled anyway
STOP_TIMEOUT = 5.0
POLL = 0.02  #: s between two state reads while a command runs


def _config(args: argparse.Namespace, names: list[str]) -> Any:
    """The rig config, with ``--mode`` applied to the named joints (checked against the registry)."""
    cfg = load_config(args, on_exit="none")
    mode: str | None = vars(args).get("mode")
    if mode is None:
        return cfg
    joints = dict(cfg.joints)
    for n in names:
        if n not in joints:
            continue  # the rig names the unknown joint with the allowed ones
        jc = joints[n]
        protocol = cfg.buses[jc.bus].protocol
        allowed = registry.family(jc.device).modes.get(protocol, ())
        if mode not in allowed:
            raise UsageError(f"joint {n}: {jc.device} over {protocol} has "
                             + (f"the modes {', '.join(allowed)}" if allowed else "no modes to choose from")
                             + f", not {mode!r}")
        joints[n] = dataclasses.replace(jc, mode=mode)
    return dataclasses.replace(cfg, joints=joints)


def wait_still(rig: Rig, j: Joint, timeout: float = STOP_TIMEOUT) -> None:
    """Poll until the joint stands still (at most ``timeout`` s)."""
    end = rig.time + timeout
    while rig.time < end:
        if not observe(j).moving:
            return
        rig.sleep(POLL)


class OneShot:
    """One joint under a one-shot command: what it found, and putting it back."""

    def __init__(self, rig: Rig, j: Joint, *, hold: bool) -> None:
        from joints.drivers.capabilities import CommunicationWatchdog

        self.rig = rig
        self.j = j
        self.hold = hold
        self.found = observe(j)
        if self.found.fault is not None:
            f = self.found.fault
            raise DeviceFault(f"joint {j.name}", f.code, f.text + "; nothing was commanded", hint=f.clears,
                              name=f.name)
        self.enabled_here = False
        self.watchdog: int | None = None
        driver = j.driver
        if isinstance(driver, CommunicationWatchdog):
            try:
                self.watchdog = driver.communication_timeout()
            except JointsError:
                self.watchdog = None
        fam = registry.family(rig.config.joints[j.name].device)
        self.settings = read_settings(j, fam)

    def enable(self) -> None:
        self.j.enable()
        self.enabled_here = not self.found.enabled

    def finish(self, *, ok: bool) -> None:
        """Done (``ok``) or interrupted: hold, or stop and put back what was found."""
        from joints.drivers.capabilities import CommunicationWatchdog

        j, driver = self.j, self.j.driver
        if ok and self.hold:
            if isinstance(driver, CommunicationWatchdog):
                driver.set_communication_timeout(0)
                warn(f"joint {j.name} is left enabled and holding with its communication watchdog OFF: nothing "
                     "feeds it now - if this host dies the drive keeps holding. Release it with "
                     f"`joints disable {self.rig.config.source} {j.name}`")
            else:
                warn(f"joint {j.name} is left enabled and holding ({driver.device} over {driver.protocol} has no "
                     f"communication watchdog). Release it with `joints disable {self.rig.config.source} {j.name}`")
            return
        try:
            j.stop()
            wait_still(self.rig, j)
        finally:
            if self.enabled_here:
                j.disable()
            elif isinstance(driver, CommunicationWatchdog) and self.watchdog is not None:
                driver.set_communication_timeout(self.watchdog)
            self._restore()

    def _restore(self) -> None:
        """Settings and modes the command changed (the joint's limits in the drive, profile, mode) put back."""
        driver = self.j.driver
        for name, value in self.settings.items():
            try:
                if driver.read(name) != value:
                    driver.write(name, value)
            except DeviceRejected:
                pass  # the drive does not take back what it showed (CANopen 0x6060 = 0: "no mode yet"; PDO maps)
            except JointsError as exc:
                warn(f"joint {self.j.name}: could not put {name} back to {value}: {exc}")


def _check(j: Joint, s: JointState) -> None:
    if s.fault is not None:
        f = s.fault
        raise DeviceFault(f"joint {j.name}", f.code, f.text, hint=f.clears, name=f.name)


def _cyclic_kind(j: Joint) -> str | None:
    from joints.drivers.capabilities import CyclicJoint

    driver = j.driver
    try:  # the protocol's property raises when the mode is not cyclic (also inside isinstance)
        return driver.cycle_kind if isinstance(driver, CyclicJoint) else None
    except CommandError:
        return None


def _tolerance(j: Joint, given: float | None) -> float:
    if given is not None:
        return given
    return 0.0005 if j.lead is not None else 0.005  # m / rad


def _result(j: Joint, s: JointState, **extra: object) -> dict[str, object]:
    return {**state_dict(j.name, s), **extra}


def run_move(rig: Rig, j: Joint, args: argparse.Namespace) -> JointState:
    from joints.drivers.capabilities import PulseMoves

    start = j.state()
    _check(j, start)
    if args.pulses:
        driver = j.driver
        if not isinstance(driver, PulseMoves):
            raise UsageError(f"joint {j.name}: {driver.device} has no pulse position modes (--pulses is for the MKS)")
        if not float(args.target).is_integer():
            raise UsageError(f"--pulses takes a whole number of pulses, got {args.target}")
        speed, acc = j.velocity_command(args.velocity if args.velocity is not None else j.motion.velocity,
                                        args.acceleration)
        if args.relative:
            driver.move_pulses(int(args.target), speed=abs(speed), acceleration=acc)
        else:
            driver.move_to_pulses(int(args.target), speed=abs(speed), acceleration=acc)
        return _wait_still(rig, j, args.timeout, start.time)
    target = start.position + args.target if args.relative else args.target
    kind = _cyclic_kind(j)
    if kind is not None:
        if kind != "position":
            raise UsageError(f"joint {j.name} is in a cyclic {kind} mode: use `joints jog`")
        return _stream_move(rig, j, target, args)
    j.move_to(target, velocity=args.velocity, acceleration=args.acceleration, deceleration=args.deceleration)
    tol = _tolerance(j, args.tolerance)
    distance = abs(target - start.position) or 1.0
    end = rig.time + args.timeout
    with Progress(100, f"{j.name} -> {target:.4g}") as bar:
        done = 0
        while True:
            rig.sleep(POLL)
            s = j.state()
            _check(j, s)
            pct = max(0, min(100, round(100 * (1 - abs(target - s.position) / distance))))
            if pct > done:
                bar.advance(pct - done)
                done = pct
            if abs(target - s.position) <= tol and not s.moving:
                return s
            if rig.time >= end:
                raise MotionTimeout(f"joint {j.name}: not at {target:.4f} after {args.timeout} s "
                                    f"(at {s.position:.4f}, {'moving' if s.moving else 'stopped'})")


def _wait_still(rig: Rig, j: Joint, timeout: float, since: float) -> JointState:
    end = rig.time + timeout
    seen_moving = False
    while True:
        rig.sleep(POLL)
        s = j.state()
        _check(j, s)
        seen_moving = seen_moving or s.moving
        if not s.moving and (seen_moving or rig.time - since > 0.5):
            return s
        if rig.time >= end:
            raise MotionTimeout(f"joint {j.name}: still moving after {timeout} s")


def _stream_move(rig: Rig, j: Joint, target: float, args: argparse.Namespace) -> JointState:
    """A cyclic position mode (csp, ip): the trapezoid planned here, one set-point per cycle."""
    from joints.devices.motion import Arrival, move_step

    driver: Any = j.driver
    dt = float(driver.group.period)
    s = j.state()
    p, v = s.position, 0.0
    cruise = args.velocity if args.velocity is not None else j.motion.velocity
    acc = args.acceleration if args.acceleration is not None else j.motion.acceleration
    dec = args.deceleration if args.deceleration is not None else j.motion.deceleration
    tol = _tolerance(j, args.tolerance)
    end = rig.time + args.timeout
    arrived = False
    while True:
        if not arrived:
            p, v, arrived = move_step(p, v, target, abs(cruise), abs(acc), abs(dec), dt, tol / 2, Arrival.ON_STEP)
        s = rig.cycle({j.name: p})[j.name]
        _check(j, s)
        if arrived and abs(target - s.position) <= tol:
            return s
        if rig.time >= end:
            raise MotionTimeout(f"joint {j.name}: not at {target:.4f} after {args.timeout} s (at {s.position:.4f})")


def run_jog(rig: Rig, j: Joint, args: argparse.Namespace) -> JointState:
    kind = _cyclic_kind(j)
    torque = args.torque is not None
    value = args.torque if torque else args.velocity
    if kind is not None:
        want = "torque" if torque else "velocity"
        if kind != want:
            raise UsageError(f"joint {j.name} is in a cyclic {kind} mode: jog it with --{kind}")
        s = j.state()
        end = rig.time + args.duration
        while rig.time < end:
            s = rig.cycle({j.name: value})[j.name]
            _check(j, s)
        for _ in range(3):  # set-point 0 for a few cycles before the stop
            s = rig.cycle({j.name: 0.0})[j.name]
        return s
    if torque:
        j.set_torque(value)
    else:
        j.set_velocity(value, acceleration=args.acceleration)
    end = rig.time + args.duration
    steps = max(1, round(args.duration / POLL))
    s = j.state()
    with Progress(steps, f"{j.name} jog {value:+.4g}") as bar:
        while rig.time < end:
            rig.sleep(min(POLL, max(end - rig.time, 0.0)))
            s = j.state()
            _check(j, s)
            bar.advance()
    return s


def _one_shot(args: argparse.Namespace, run: Any) -> int:
    cfg = _config(args, [args.joint])
    with open_rig(args, config=cfg) as rig:
        j = joint(rig, args.joint)
        shot = OneShot(rig, j, hold=args.hold)
        ok = False
        try:
            shot.enable()
            s = run(rig, j, args)
            ok = True
        finally:
            shot.finish(ok=ok)
        final = observe(j)
    if args.json:
        emit_json(_result(j, final, reached=s.position, held=args.hold))
    else:
        note(f"{j.name}: at {cell(s.position)}; now {'enabled, holding' if final.enabled else 'disabled'}")
    return 0


def cmd_move(args: argparse.Namespace) -> int:
    return _one_shot(args, run_move)


def cmd_jog(args: argparse.Namespace) -> int:
    if (args.velocity is None) == (args.torque is None):
        raise UsageError("jog needs either --velocity or --torque")
    return _one_shot(args, run_jog)


def cmd_enable(args: argparse.Namespace) -> int:
    cfg = _config(args, args.joints)
    with open_rig(args, config=cfg) as rig:
        for name in args.joints:
            j = joint(rig, name)
            shot = OneShot(rig, j, hold=True)
            ok = False
            try:
                shot.enable()
                ok = True
            finally:
                shot.finish(ok=ok)
    return 0


def cmd_disable(args: argparse.Namespace) -> int:
    with open_rig(args) as rig:
        for name in args.joints:
            j = joint(rig, name)
            observe(j)  # what the drive says (a CANopen node is not brought up: stopped by SDO)
            j.stop()
            wait_still(rig, j)
            j.disable()
    return 0


def cmd_stop(args: argparse.Namespace) -> int:
    with open_rig(args) as rig:
        for name in args.joints:
            j = joint(rig, name)
            observe(j)
            if args.now:
                j.emergency_stop()
            else:
                j.stop()
    return 0


def cmd_clear(args: argparse.Namespace) -> int:
    with open_rig(args) as rig:
        for name in args.joints:
            j = joint(rig, name)
            j.clear_faults()
            s = observe(j)
            if s.fault is not None:
                raise DeviceFault(f"joint {name}", s.fault.code, s.fault.text + "; it did not clear",
                                  hint=s.fault.clears, name=s.fault.name)
    return 0


def _motion_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--hold", action="store_true",
                   help="leave the joint enabled and holding (its watchdog switched off) instead of disabling it")
    p.add_argument("--mode", help="operating mode for this command where the protocol has several "
                                  "(CANopen: pp, pv, pt, csp, csv, cst, ip)")
    p.add_argument("--acceleration", type=positive, help="rad/s^2 (m/s^2 with a lead; default: the config's)")
    add_json(p)


def register(sub: Any) -> None:
    m = command(sub, "move", help="move a joint to a position (SI: rad, m with a lead) and wait until it is there",
                example="joints move robot.toml shoulder 1.57\njoints move robot.toml shoulder -0.5 --relative\n"
                        "joints move robot.toml axis 3200 --pulses --relative   # MKS pulse mode\n"
                        "joints move robot.toml shoulder 0.5 --mode csp --hold", func=cmd_move)
    add_config(m)
    m.add_argument("joint")
    m.add_argument("target", type=number, help="position (or distance with --relative)")
    m.add_argument("--relative", action="store_true", help="a distance from where the joint is")
    m.add_argument("--pulses", action="store_true", help="MKS: the target in microstep pulses (position modes 1/2)")
    m.add_argument("--velocity", type=positive, help="profile speed (default: the config's motion.velocity)")
    m.add_argument("--deceleration", type=positive)
    m.add_argument("--tolerance", type=positive, help="arrival window (default 0.005 rad, 0.0005 m)")
    m.add_argument("--timeout", type=positive, default=30.0, help="s to reach the target (default 30)")
    _motion_options(m)

    g = command(sub, "jog", help="run a joint at a velocity (or torque) for a while, then stop",
                example="joints jog robot.toml shoulder --velocity 0.5 --duration 2\n"
                        "joints jog robot.toml shoulder --torque 1.5 --duration 0.5", func=cmd_jog)
    add_config(g)
    g.add_argument("joint")
    g.add_argument("--velocity", type=number, help="rad/s (m/s with a lead)")
    g.add_argument("--torque", type=number, help="N*m (N with a lead)")
    g.add_argument("--duration", type=nonnegative, default=1.0, help="s (default 1)")
    _motion_options(g)

    for name, func, text, example in (
            ("enable", cmd_enable, "enable joints and leave them holding (their watchdog switched off)",
             "joints enable robot.toml shoulder"),
            ("disable", cmd_disable, "stop and disable joints", "joints disable robot.toml shoulder elbow"),
            ("stop", cmd_stop, "stop joints (decelerated; --now: emergency stop); they stay enabled",
             "joints stop robot.toml shoulder\njoints stop robot.toml shoulder --now"),
            ("clear", cmd_clear, "clear joints' faults (then enable them again)", "joints clear robot.toml shoulder")):
        c = command(sub, name, help=text, example=example, func=func)
        add_config(c)
        c.add_argument("joints", nargs="+", metavar="joint")
        if name == "stop":
            c.add_argument("--now", action="store_true", help="emergency stop (as fast as the drive can)")
        if name == "enable":
            c.add_argument("--mode", help="operating mode where the protocol has several (CANopen)")


__all__ = ["OneShot", "register", "wait_still"]
