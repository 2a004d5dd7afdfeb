"""``joints bench``: every speed ratio of issue 23, each against a reference measured in the same run.

Rule: ratios, never absolute times (machines and their load vary from run to run); every
reference is timed interleaved with what it is compared to, the process pinned to one core. An env
row's figures are the median over ``repeats`` pairs, each an env block and its references timed right
after it, so that a machine whose speed changes within a run slows both sides of a pair alike (the
best env block beside the best reference could pair a fast moment with a slow one); the world and
codec rows take the best of ``repeats``. The method of the env rows (the issue's): ``gym.make(id)``
with its defaults (wrappers included), uniform random actions over the whole action space from a fixed seed,
resets not timed; the reference is ``raw_steps`` raw ``mujoco.mj_step`` calls on the same model
and a fresh ``MjData``. Real-time factors (simulated seconds per wall second) are printed beside
the ratios, for users, not as goals.

The envs are reached through gymnasium by id (``"envs:joints/ErobReach-v0"`` imports the module
that registers them): the ``joints`` package never imports ``envs``.
"""

from __future__ import annotations

import math
import os
import platform
import sys
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

__all__ = ["ENV_ROWS", "Row", "pin_one_core", "run"]

#: the env rows: (gymnasium id, goal of substeps/s / raw mj_step/s)
ENV_ROWS = (("joints/ErobReach-v0", 0.6), ("joints/ErobArmReach-v0", 0.5), ("joints/DiffDriveGoal-v0", 0.6))
#: the shipped config (``joints/configs/<stem>.toml``) of each env row
SHIPPED_CONFIGS = {"joints/ErobReach-v0": "erob_reach", "joints/ErobArmReach-v0": "erob_arm_reach",
                   "joints/DiffDriveGoal-v0": "zlac_diffdrive"}
#: the goals of the Python overhead per env step [s]: the step's wall time less its substeps of raw mj_step
OVERHEAD_GOALS = {"joints/ErobReach-v0": 30e-6, "joints/ErobArmReach-v0": 75e-6}
#: the control period the speed goals were first measured at [s] (issue 23): rows at this period too,
#: on a bus that carries it, so that a longer shipped period (more substeps per step) is not counted as speed
BASELINE_PERIOD = 0.02
#: the reference env from gymnasium's own MuJoCo suite (no drive emulation), measured in the same run
REFERENCE_ENV = "Reacher-v5"
WORLD_GOAL = 0.8
CODEC_GOAL = 3.0
BATCH_GOAL = 0.6
BATCH_RIGS = (16, 256)
ENV_MODULE = "envs"  #: the module that registers the ``joints/`` env ids


@dataclass
class Row:
    """One line of the table: a measured figure against its goal (None: not measured); ``at_most``: the
    goal is an upper bound (the overhead rows, in us), else a lower bound (the ratios)."""

    measure: str
    ratio: float | None
    goal: float | None
    detail: str = ""
    at_most: bool = False

    @property
    def met(self) -> bool | None:
        if self.ratio is None or self.goal is None:
            return None
        return self.ratio <= self.goal if self.at_most else self.ratio >= self.goal

    def cells(self) -> tuple[str, str, str, str]:
        ratio = "—" if self.ratio is None else f"{self.ratio:.2f}" if not self.at_most else f"{self.ratio:.0f} us"
        goal = "" if self.goal is None else f"<= {self.goal:g} us" if self.at_most else f">= {self.goal:g}"
        met = {None: "" if self.goal is None else "?", True: "met", False: "NOT met"}[self.met]
        return self.measure, ratio, goal, met


def pin_one_core() -> tuple[int | None, set[int] | None]:
    """Pin this process to one core (the lowest it may run on): (the core, the cores it had), or
    (None, None) where the platform cannot."""
    if not hasattr(os, "sched_setaffinity"):
        return None, None
    before = set(os.sched_getaffinity(0))
    cpu = min(before)
    os.sched_setaffinity(0, {cpu})
    return cpu, before


def best_of(fns: Sequence[Callable[[], float]], repeats: int) -> list[float]:
    """Best (smallest) of ``repeats`` timings of each ``fn`` (which returns the seconds it measured),
    interleaved so that a burst of load hits every side of a ratio alike."""
    best = [math.inf] * len(fns)
    for _ in range(repeats):
        for i, fn in enumerate(fns):
            best[i] = min(best[i], fn())
    return best


def paired(fns: Sequence[Callable[[], float]], repeats: int) -> list[list[float]]:
    """``repeats`` timings of each ``fn`` (which returns the seconds it measured), interleaved: per repeat, one
    of each, one right after the other (``[repeat][fn]``)."""
    return [[fn() for fn in fns] for _ in range(repeats)]


def median_pair(count: int, ratio: Callable[[int], float]) -> int:
    """The index of the median of ``count`` pairs ordered by ``ratio(i)`` (the upper middle one for an even
    count): the pair whose figures a row reports, not a mix of pairs."""
    return sorted(range(count), key=ratio)[count // 2]


def _raw(model: Any, steps: int, nstep: int = 1) -> Callable[[], float]:
    """``steps`` raw mj_step substeps on ``model`` with a fresh MjData: the seconds they took. ``nstep``
    1: one Python call per substep (the reference of the ratios); more: ``mj_step(model, data, nstep)``
    calls of that many substeps each (the distance to C-level physics)."""
    import mujoco

    calls = max(1, steps // nstep)

    def timed() -> float:
        data = mujoco.MjData(model)
        step = mujoco.mj_step
        if nstep == 1:
            t = time.perf_counter()
            for _ in range(calls):
                step(model, data)
        else:
            t = time.perf_counter()
            for _ in range(calls):
                step(model, data, nstep)
        return (time.perf_counter() - t) * steps / (calls * nstep)

    return timed


def _raw_many(models: Sequence[Any], steps: int, run: int = 1) -> Callable[[], float]:
    """About ``steps`` raw mj_step calls spread evenly over ``models`` (fresh MjData each), ``run`` substeps of
    one model in a row before the next (a batch's pattern: each rig's world runs its period's substeps in one go,
    rig after rig; one substep per model in turn would make the reference pay the caches' misses the batch does
    not): seconds for ``steps``."""
    import mujoco

    rounds = max(1, steps // (len(models) * run))

    def timed() -> float:
        pairs = [(m, mujoco.MjData(m)) for m in models]
        step = mujoco.mj_step
        t = time.perf_counter()
        for _ in range(rounds):
            for m, d in pairs:
                for _ in range(run):
                    step(m, d)
        return (time.perf_counter() - t) * steps / (rounds * len(models) * run)

    return timed


def _substep_counter(env: Any) -> Callable[[], int]:
    """The physics substeps ``env`` (a joints env, a batched one, or a gymnasium MuJoCo env) has run so far."""
    u = env.unwrapped
    if hasattr(u, "envs"):  # batched: every rig's world
        worlds = [e.rig.sim for e in u.envs]
        return lambda: sum(w.steps for w in worlds)
    if hasattr(u, "rig"):
        world = u.rig.sim
        return lambda: int(world.steps)
    frames = int(u.frame_skip)  # gymnasium's MujocoEnv: frame_skip mj_step per step, no more
    count = [0]
    step = u.step

    def counting(*args: Any, **kwargs: Any) -> Any:
        count[0] += frames
        return step(*args, **kwargs)

    u.step = counting
    return lambda: count[0]


@dataclass
class EnvTiming:
    """What each timed block of env steps took, in order: its wall time, the substeps they really ran, and the
    wall time with the block's resets included (and the reset substeps left out of ``substeps``)."""

    steps: int
    seconds: list[float] = field(default_factory=list)
    substeps: list[int] = field(default_factory=list)
    with_resets: list[float] = field(default_factory=list)


def _env_block(env: Any, steps: int, seed: int, out: EnvTiming | None = None) -> Callable[[], float]:
    """``steps`` env.step calls with uniform random actions from ``seed`` (resets untimed): seconds.
    ``out``: each block's seconds, the substeps the steps ran and the seconds with resets timed."""
    import numpy as np

    space = env.action_space
    rng = np.random.default_rng(seed)
    actions = rng.uniform(space.low, space.high, (steps, *space.shape)).astype(space.dtype)
    env.reset(seed=seed)
    count = _substep_counter(env)

    def timed() -> float:
        total = 0.0
        resets = 0.0
        substeps = 0
        step = env.step
        clock = time.perf_counter
        for a in actions:
            n = count()
            t = clock()
            _obs, _r, terminated, truncated, _info = step(a)
            total += clock() - t
            substeps += count() - n
            if np.any(terminated) or np.any(truncated):
                t = clock()
                env.reset()
                resets += clock() - t
        if out is not None:
            out.seconds.append(total)
            out.substeps.append(substeps)
            out.with_resets.append(total + resets)
        return total

    return timed


def _env_rows(name: str, env: Any, model: Any, nominal: int, steps: int, raw_steps: int, repeats: int, seed: int,
              goal: float | None, overhead_goal: float | None, sim_dt: float, rigs: int = 1) -> Iterator[Row]:
    """The rows of one env: substeps/s over raw mj_step/s (per Python call, and per ``nstep`` call), the same
    with resets timed, and the Python overhead per env step: each the median of its pairs' (:func:`paired`)."""
    timing = EnvTiming(steps)
    models = list(model) if isinstance(model, (list, tuple)) else [model]
    fns = [_env_block(env, steps, seed, timing),
           _raw(models[0], raw_steps) if len(models) == 1 else _raw_many(models, raw_steps, nominal),
           _raw(models[0], raw_steps, nominal)]
    pairs = paired(fns, repeats)
    # per pair: s per substep with one Python call each (the reference), and in mj_step(model, data, nstep)
    raws = [p[1] / raw_steps for p in pairs]
    nsteps = [p[2] / raw_steps for p in pairs]
    subs, envs, resets = timing.substeps, timing.seconds, timing.with_resets
    ratios = [r * n / e for r, n, e in zip(raws, subs, envs)]
    overheads = [(e - n * r) / steps for r, n, e in zip(raws, subs, envs)]  # per env step (per batch of rigs)
    ratio, overhead = _median(ratios), _median(overheads)
    to_nstep = _median([ns * n / e for ns, n, e in zip(nsteps, subs, envs)])
    with_resets = _median([r * n / w for r, n, w in zip(raws, subs, resets)])
    # the median pair's figures for the detail (a pair, not a mix of pairs)
    k = median_pair(len(pairs), ratios.__getitem__)
    t_env, raw, nstep, sub = envs[k], raws[k], nsteps[k], subs[k]
    extra = sub / (steps * rigs) - nominal
    yield Row(f"{name}: env substeps/s ÷ raw `mj_step`/s", ratio, goal,
              f"{sub / t_env:,.0f} substeps/s vs raw {1 / raw:,.0f}/s ({to_nstep:.2f} of "
              f"`mj_step(m, d, nstep={nominal})`, {1 / nstep:,.0f}/s); {sub / (steps * rigs):.3f} substeps per "
              f"step ({nominal} nominal{f', {extra:+.3f} beyond it' if abs(extra) > 1e-9 else ''}); "
              f"{steps / t_env:,.0f} env steps/s, real-time factor {steps * rigs * sim_dt / t_env:,.0f}x")
    yield Row(f"{name}: the same with resets timed", with_resets, None,
              f"{resets[k] - t_env:.3f} s of resets beside {t_env:.3f} s of steps (reset substeps not counted)")
    yield Row(f"{name}: overhead per env step (wall time - substeps x raw `mj_step`)", overhead * 1e6,
              None if overhead_goal is None else overhead_goal * 1e6,
              f"{t_env / steps * 1e6:.1f} us per step - {sub / steps:.2f} x {raw * 1e6:.2f} us (the median pair; "
              f"pairs {', '.join(f'{o * 1e6:.0f}' for o in overheads)} us)",
              at_most=True)


def _baseline_config(env_id: str) -> tuple[Any, str] | None:
    """The env's shipped config on a bus that carries :data:`BASELINE_PERIOD` (eRob: its CAN protocol at
    1 Mbit/s), and that bus; None where the shipped bus already carries it or the family has no such bus."""
    import copy
    from importlib import resources

    from joints import registry
    from joints.errors import ConfigError

    if sys.version_info >= (3, 11):
        import tomllib
    else:  # pragma: no cover
        import tomli as tomllib

    stem = SHIPPED_CONFIGS.get(env_id)
    if stem is None:
        return None
    cfg = tomllib.loads((resources.files("joints.configs") / f"{stem}.toml").read_text(encoding="utf-8"))
    devices = {j["device"] for j in cfg["joints"].values()}
    shipped = f"{next(iter(cfg['buses'].values()))['protocol']} as shipped"
    for proto in registry.protocols():
        if registry.PROTOCOLS[proto].medium != "can" or not all(proto in registry.family(d).protocols
                                                                for d in devices):
            continue
        on_can = copy.deepcopy(cfg)
        on_can["buses"] = {"can": {"protocol": proto, "bitrate": 1_000_000}}
        for j in on_can["joints"].values():
            j["bus"] = "can"
        try:
            check_rate(on_can, BASELINE_PERIOD)
        except ConfigError:
            continue
        return on_can, f"{proto} at 1 Mbit/s"
    try:
        check_rate(cfg, BASELINE_PERIOD)
    except ConfigError:
        return None  # no bus of this env carries the baseline period (the env would refuse it): no row
    return cfg, shipped


def env_rows(*, steps: int, raw_steps: int, repeats: int, seed: int = 0) -> Iterator[Row]:
    """Env substeps/s over raw mj_step/s on the same model, per registered env, at its shipped rate and at
    :data:`BASELINE_PERIOD`; then gymnasium's :data:`REFERENCE_ENV` by the same method."""
    import gymnasium as gym

    for env_id, goal in ENV_ROWS:
        env = gym.make(f"{ENV_MODULE}:{env_id}")
        try:
            u: Any = env.unwrapped
            hz = 1.0 / u.dt
            yield from _env_rows(f"`{env_id}` ({hz:g} Hz)", env, u.model, round(u.dt / u.model.opt.timestep),
                                 steps, raw_steps, repeats, seed, goal, OVERHEAD_GOALS.get(env_id), u.dt)
        finally:
            env.close()
        if abs(u.dt - BASELINE_PERIOD) < 1e-9:
            continue
        found = _baseline_config(env_id)
        if found is None:
            continue
        cfg, bus = found
        env = gym.make(f"{ENV_MODULE}:{env_id}", config=cfg, control_period=BASELINE_PERIOD)
        try:
            u = env.unwrapped
            yield from _env_rows(f"`{env_id}` ({1 / BASELINE_PERIOD:g} Hz, {bus})", env, u.model,
                                 round(u.dt / u.model.opt.timestep), steps, raw_steps, repeats, seed, goal,
                                 OVERHEAD_GOALS.get(env_id), u.dt)
        finally:
            env.close()
    yield from reference_rows(steps=steps, raw_steps=raw_steps, repeats=repeats, seed=seed)


def reference_rows(*, steps: int, raw_steps: int, repeats: int, seed: int = 0) -> Iterator[Row]:
    """Gymnasium's :data:`REFERENCE_ENV` (its MuJoCo suite, no drive emulation) by the env rows' method."""
    import gymnasium as gym

    name = f"`{REFERENCE_ENV}` (gymnasium, reference)"
    try:
        env = gym.make(REFERENCE_ENV)
    except Exception as exc:  # noqa: BLE001 - any missing piece of gymnasium[mujoco] means: not measured
        yield Row(name, None, None, f"not available: {type(exc).__name__}: {exc}")
        return
    try:
        u: Any = env.unwrapped
        yield from _env_rows(name, env, u.model, int(u.frame_skip), steps, raw_steps, repeats, seed, None, None, u.dt)
    finally:
        env.close()


def batched_rows(*, steps: int, raw_steps: int, repeats: int, rigs: Sequence[int] = BATCH_RIGS,
                 seed: int = 0) -> Iterator[Row]:
    """N rigs stepped by one batched env (gymnasium's vector entry point) against raw mj_step of N models."""
    for n in rigs:
        yield from batched_row(steps=steps, raw_steps=raw_steps, repeats=repeats, rigs=n, seed=seed)


def batched_row(*, steps: int, raw_steps: int, repeats: int, rigs: int = BATCH_RIGS[0],
                seed: int = 0) -> Iterator[Row]:
    """``rigs`` rigs of the first env row in one batched env (gymnasium's vector entry point)."""
    import gymnasium as gym

    env_id = ENV_ROWS[0][0]
    name = f"{rigs} rigs batched in one process (`{env_id}`)"
    try:
        vec = gym.make_vec(f"{ENV_MODULE}:{env_id}", num_envs=rigs, vectorization_mode="vector_entry_point")
    except (gym.error.Error, ValueError, TypeError, AttributeError) as exc:
        yield Row(name, None, BATCH_GOAL, f"no batched env: {exc}")
        return
    try:
        u: Any = vec.unwrapped
        models = list(u.models)
        blocks = max(2, steps // rigs)
        rows = list(_env_rows(name, vec, models, round(u.dt / models[0].opt.timestep), blocks,
                              max(raw_steps, 2 * rigs), repeats, seed, BATCH_GOAL, None, u.dt, rigs))
        yield rows[0]
        yield Row(f"{name}: overhead per rig step", rows[2].ratio / rigs if rows[2].ratio is not None else None,
                  None, rows[2].detail + f" (per batch of {rigs})", at_most=True)
    finally:
        vec.close()


#: the states of the world row: name -> how to put a joint there (after enable and its 500 ms)
WORLD_STATES = ("disabled", "holding", "speed", "profile absolute")


def _erob_rig() -> Any:
    import joints

    cfg = {
        "backend": "sim",
        "sim": {"model": "erob_stand.xml", "timestep": 0.001, "direct": True},
        "buses": {"rs485": {"protocol": "modbus-rtu", "port": "sim"}},
        "joints": {"joint1": {"device": "erob", "model": "eRob80H100", "bus": "rs485", "address": 1,
                              "limits": {"position": [-1000.0, 1000.0], "velocity": 5.0, "torque": 40.0}}},
    }
    return joints.open(cfg)


def _into(rig: Any, state: str) -> None:
    rig.reset()
    j = rig.joints["joint1"]
    if state == "disabled":
        return
    j.enable()
    rig.sleep(0.6)
    if state == "speed":
        j.set_velocity(2.0, acceleration=20.0)
        rig.sleep(0.5)
    elif state == "profile absolute":
        j.move_to(900.0, velocity=2.0, acceleration=20.0, deceleration=20.0)  # moves for 450 s
        rig.sleep(0.5)


def world_row(*, raw_steps: int, repeats: int) -> Row:
    """World.step of one eRob in each state over raw mj_step on the same model."""
    rig = _erob_rig()
    try:
        world = rig.sim
        ratios: list[float] = []
        rates: list[str] = []
        for state in WORLD_STATES:
            def timed(state: str = state) -> float:
                _into(rig, state)
                t = time.perf_counter()
                world.step(raw_steps)
                return time.perf_counter() - t

            t_world, t_raw = best_of([timed, _raw(world.model, raw_steps)], repeats)
            ratios.append(t_raw / t_world)
            rates.append(f"{raw_steps / t_world:,.0f}")
        raw_s = raw_steps / t_raw
        return Row("world ratio, one eRob, " + " / ".join(WORLD_STATES), min(ratios), WORLD_GOAL,
                   " / ".join(f"{r:.2f}" for r in ratios) + f" (substeps/s {' / '.join(rates)}; raw {raw_s:,.0f})")
    finally:
        rig.close()


def _codec_benches() -> tuple[list[Callable[[int], None]], str]:
    """FC03 of the eRob status block (25 registers from 0x0060): joints' codec and pymodbus', as
    ``fn(n)`` loops - host role (encode the request, decode the reply) and device role (decode the
    request, encode the reply); the frames are checked equal before anything is timed."""
    import pymodbus
    from pymodbus.framer import FramerRTU
    from pymodbus.pdu import DecodePDU
    from pymodbus.pdu.register_message import ReadHoldingRegistersRequest, ReadHoldingRegistersResponse

    from joints.codecs import modbus as mb

    slave, start, count = 2, 0x0060, 25
    values = tuple((0x1111 * (i + 1)) & 0xFFFF for i in range(count))
    request = mb.encode(mb.ReadHoldingRegisters(slave, start, count))
    reply = mb.encode(mb.ReadRegistersReply(slave, mb.READ_HOLDING_REGISTERS, values))
    client, server = FramerRTU(DecodePDU(False)), FramerRTU(DecodePDU(True))
    assert client.buildFrame(ReadHoldingRegistersRequest(address=start, count=count, dev_id=slave)) == request
    assert tuple(client.handleFrame(reply, slave, 0)[1].registers) == values  # type: ignore[union-attr]
    pdu = server.handleFrame(request, slave, 0)[1]
    assert (pdu.address, pdu.count) == (start, count)  # type: ignore[union-attr]
    assert server.buildFrame(ReadHoldingRegistersResponse(registers=list(values), dev_id=slave)) == reply

    def joints_host(n: int) -> None:
        codec = mb.ModbusRtuCodec(mb.Role.HOST)
        encode, req_cls, expect, feed, next_message = (mb.encode, mb.ReadHoldingRegisters, codec.expect_reply_to,
                                                       codec.feed, codec.next_message)
        for _ in range(n):
            req = req_cls(slave, start, count)
            encode(req)
            expect(req)
            feed(reply)
            _ = next_message().values  # type: ignore[union-attr]

    def pymodbus_host(n: int) -> None:
        framer = FramerRTU(DecodePDU(False))
        build, handle = framer.buildFrame, framer.handleFrame
        for _ in range(n):
            build(ReadHoldingRegistersRequest(address=start, count=count, dev_id=slave))
            _ = handle(reply, slave, 0)[1].registers  # type: ignore[union-attr]

    def joints_device(n: int) -> None:
        codec = mb.ModbusRtuCodec(mb.Role.DEVICE)
        encode, reply_cls, feed, next_message = mb.encode, mb.ReadRegistersReply, codec.feed, codec.next_message
        fc = mb.READ_HOLDING_REGISTERS
        for _ in range(n):
            feed(request)
            req = next_message()
            encode(reply_cls(req.slave, fc, values))  # type: ignore[union-attr]

    def pymodbus_device(n: int) -> None:
        framer = FramerRTU(DecodePDU(True))
        build, handle = framer.buildFrame, framer.handleFrame
        for _ in range(n):
            req = handle(request, slave, 0)[1]
            build(ReadHoldingRegistersResponse(registers=list(values), dev_id=req.dev_id))  # type: ignore[union-attr]

    return [joints_host, pymodbus_host, joints_device, pymodbus_device], str(pymodbus.__version__)


def _per_call(fns: Sequence[Callable[[int], None]], repeats: int, min_time: float) -> list[float]:
    """Best-of-``repeats`` seconds per iteration of each ``fn(n)`` (n grown until a run lasts ``min_time``)."""
    def sized(fn: Callable[[int], None]) -> Callable[[], float]:
        n = 1
        while True:
            t = time.perf_counter()
            fn(n)
            if time.perf_counter() - t >= min_time:
                break
            n *= 2

        def timed() -> float:
            t = time.perf_counter()
            fn(n)
            return (time.perf_counter() - t) / n

        return timed

    return best_of([sized(fn) for fn in fns], repeats)


def codec_row(*, repeats: int, min_time: float) -> Row:
    """The Modbus RTU codec against pymodbus', FC03 of the eRob status block, host and device roles."""
    name = "Modbus codec vs pymodbus, FC03 host / device"
    try:
        fns, version = _codec_benches()
    except ImportError:
        return Row(name, None, CODEC_GOAL, "pymodbus not installed")
    jh, ph, jd, pd = _per_call(fns, repeats, min_time)
    host, device = ph / jh, pd / jd
    return Row(name, min(host, device), CODEC_GOAL,
               f"{host:.1f}x / {device:.1f}x faster than pymodbus {version} "
               f"({jh * 1e6:.1f} / {jd * 1e6:.1f} us per FC03)")


# -- the bus planner ------------------------------------------------------------------------------

#: control rate the planner checks when none is given [Hz] (the envs' 20 ms period)
PLAN_RATE = 50.0


@dataclass
class BusPlan:
    """One bus of a config: its traffic per control cycle, its time and what fits."""

    bus: str
    protocol: str
    line: str  #: "115200 baud 8N1" / "1000000 bit/s"
    joints: int
    frames: int  #: frames per cycle (requests and replies)
    data_bytes: int  #: bytes of those frames (serial: whole RTU frames; CAN: data fields)
    load: Any  #: :class:`joints.transports.can_timing.CycleLoad` of the wire alone at the checked rate
    transactions: int = 0  #: replies per cycle (each costs a drive turnaround and the adapter's latency)
    overhead: float = 0.0  #: s per cycle of drive turnarounds and adapter latency

    @property
    def wire(self) -> float:
        """s one cycle's frames occupy the wire (worst-case CAN stuffing; Modbus t3.5 included)."""
        return float(self.load.bits_worst / self.load.bitrate)

    @property
    def cycle(self) -> float:
        """s of one control cycle on this bus: wire time plus turnarounds and adapter latency."""
        return self.wire + self.overhead

    def share(self, period: float) -> float:
        """The fraction of a control ``period`` one cycle takes (1.0 = all of it)."""
        return self.cycle / period

    def max_rate(self, fraction: float = 1.0) -> float:
        """The highest control rate [Hz] at which a cycle takes at most ``fraction`` of the period."""
        return fraction / self.cycle if self.cycle > 0 else math.inf

    def text(self, rate: float) -> str:
        period = 1.0 / rate
        per_joint = self.cycle / self.joints if self.joints else 0.0
        fit = int(period // per_joint) if per_joint else 0
        verdict = "fits" if self.cycle <= period else "does NOT fit"
        return (f"bus {self.bus} ({self.protocol}, {self.line}): {self.joints} joint(s), {self.frames} frames / "
                f"{self.data_bytes} bytes per control cycle -> {self.wire * 1e3:.2f} ms on the wire + "
                f"{self.overhead * 1e3:.2f} ms of drive turnaround and adapter latency ({self.transactions} "
                f"transactions) = {self.cycle * 1e3:.2f} ms; at {rate:g} Hz {self.share(period):.0%} of the period "
                f"({verdict}); these joints fit up to {self.max_rate():,.0f} Hz ({self.max_rate(CYCLE_BUDGET):,.0f} Hz "
                f"within {CYCLE_BUDGET:.0%}); at {rate:g} Hz up to {fit} joint(s) like these fit")


#: the share of the control period the shipped env configs keep one cycle within (the rest is margin)
CYCLE_BUDGET = 0.8


#: the counted cycle's velocity commands, as a share of each joint's velocity limit: a change from the warm-up
#: cycle's 0, as a policy's commands change every step (a drive that takes a ramp per change - the ZLAC's
#: acceleration times - sends it too)
PLAN_SPEED = 0.1


def _cycle(rig: Any, mode: str = "position", speed: float = 0.0) -> None:
    """One control cycle of every joint as the envs run it: a command in ``mode`` (velocities: ``speed`` x the
    joint's velocity limit, 1 unit/s without one), then every joint's state."""
    from joints.drivers.capabilities import GroupedChannel, SyncVelocityGroup

    velocities = {}
    for name, j in rig.joints.items():
        d = j.driver
        v = speed * (j.limits.velocity or 1.0)
        if isinstance(d, GroupedChannel) and isinstance(d.group, SyncVelocityGroup):
            velocities[name] = v  # wheels: both targets in one command (as the diffdrive env)
        elif mode == "velocity":
            j.set_velocity(v)
        elif mode == "torque":
            j.set_torque(0.0)
        else:
            s = j.last_state or j.state()
            j.move_to(s.position)
    if velocities:
        rig.set_velocities(velocities)
    rig.read_states()


_PLANS: dict[tuple[str, str, str], list[BusPlan]] = {}


def plan(config: Any, rate: float | None = None, *, mode: str = "position") -> list[BusPlan]:
    """The traffic and time of one control cycle per bus of ``config``, from the frames the drivers really
    send (run on the config's twins, with the action ``mode``'s commands), timed with the wire-time model
    of each medium: serial characters at the bus's framing and Modbus RTU's t3.5
    (:mod:`joints.transports.serial_timing`), CAN frames with worst-case bit stuffing
    (:func:`joints.transports.can_timing.cycle_load`), plus per transaction the drive's turnaround (its
    profile) and the host adapter's latency (the bus's ``adapter_latency`` or the medium's default)."""
    import joints
    from joints import registry
    from joints.config import RigConfig, load, parse

    rate = rate or PLAN_RATE
    if not rate > 0:
        raise ValueError(f"the control rate must be > 0 Hz, got {rate!r}")
    if isinstance(config, RigConfig):
        cfg = config.with_backend("sim")
    elif isinstance(config, Mapping):
        cfg = parse(config, backend="sim")
    else:
        cfg = load(Path(config), backend="sim")
    key = (repr(cfg), mode, "")
    cached = _PLANS.get(key)
    if cached is None:
        cached = _PLANS[key] = _measure(joints, registry, cfg, mode)
    return [_at_rate(p, rate) for p in cached]


def cycle_times(config: Any, mode: str = "position") -> dict[str, BusPlan]:
    """Bus name -> the plan of one control cycle of ``config`` on it (:attr:`BusPlan.cycle`: its time in s):
    what the envs and the rig's fixed-rate helpers check their period against."""
    return {p.bus: p for p in plan(config, PLAN_RATE, mode=mode)}


def check_rate(config: Any, period: float, mode: str = "position") -> dict[str, BusPlan]:
    """Refuse (:class:`~joints.errors.ConfigError` with the planner's numbers and the ways out) a control
    ``period`` [s] that one cycle of ``config`` (:func:`cycle_times`; a rig's ``config`` too) does not fit on
    every bus; returns the plans. In sim a bus with ``timing = "ideal"`` takes no time and always fits (its
    plan is left out). Without MuJoCo (a hardware-only install) the cycle cannot be planned on the twins: a
    warning says so, nothing is refused and no plan is returned."""
    import logging

    from joints.config import RigConfig, load, parse
    from joints.errors import ConfigError, MissingDependencyError

    if isinstance(config, RigConfig):
        cfg = config
    elif isinstance(config, Mapping):
        cfg = parse(config)
    else:
        cfg = load(Path(config))
    try:
        plans = cycle_times(cfg, mode)
    except MissingDependencyError as exc:
        logging.getLogger("joints").warning(
            "cannot check the control rate against the buses (the planner runs the config's twins): %s", exc)
        return {}
    out = {}
    for name, p in plans.items():
        bus = cfg.buses[name]
        if (cfg.backend == "sim" or bus.backend == "sim") and bus.timing == "ideal":
            continue
        out[name] = p
        if p.cycle <= period:
            continue
        raise ConfigError(
            f"a {1.0 / period:g} Hz control loop does not fit this bus ({p.protocol}, {p.line}): one cycle of "
            f"{mode} commands and state reads of its {p.joints} joint(s) takes {p.cycle * 1e3:.1f} ms "
            f"({p.wire * 1e3:.1f} ms on the wire + {p.overhead * 1e3:.1f} ms of drive turnaround and adapter "
            f"latency over {p.transactions} transactions), {p.share(period):.0%} of the {period * 1e3:g} ms "
            f"period; it fits up to {p.max_rate():.0f} Hz. Ways out: a higher baud rate, another protocol "
            f"(eRob CAN or CANopen at 1 Mbit/s), fewer joints per bus, a lower rate (a period of at least "
            f"{p.cycle:.3f} s), or another action mode", file=cfg.source, key=f"buses.{name}")
    return out


def _at_rate(p: BusPlan, rate: float) -> BusPlan:
    from joints.transports.can_timing import CycleLoad

    load = CycleLoad(p.load.bits_best, p.load.bits_worst, 1.0 / rate, p.load.bitrate)
    return BusPlan(p.bus, p.protocol, p.line, p.joints, p.frames, p.data_bytes, load, p.transactions, p.overhead)


def _can_frame(record: Any) -> Any:
    import can

    return can.Message(arbitration_id=record.ident, data=record.data, is_extended_id=False)


def _measure(joints: Any, registry: Any, cfg: Any, mode: str) -> list[BusPlan]:
    from joints.link.trace import TraceRecord
    from joints.transports import can_timing, serial_timing

    with joints.open(cfg) as rig:
        for j in rig.joints.values():
            j.enable()
        rig.sleep(0.6)
        _cycle(rig, mode)  # the first cycle also configures modes and profiles: not counted
        records: list[TraceRecord] = []
        rig.trace(records.append)
        _cycle(rig, mode, PLAN_SPEED)
        rig.trace(None)
        out = []
        for name, b in rig.config.buses.items():
            mine = [r for r in records if r.bus == rig.buses[name].link.name]
            on_bus = {c.address: c for c in rig.config.joints.values() if c.bus == name}
            proto = registry.protocol(b.protocol)
            sizes = [len(r.data) for r in mine]
            period = 1.0 / PLAN_RATE
            if proto.medium == "can":
                load = can_timing.cycle_load(sizes, period=period, bitrate=b.bitrate)
                line = f"{b.bitrate} bit/s"
            else:
                load = serial_timing.cycle_load(sizes, period=period, baudrate=b.baudrate, parity=b.parity,
                                                stopbits=b.stopbits, silence=proto.silence)
                line = f"{b.baudrate} baud 8{b.parity}{b.stopbits}" + (", t3.5" if proto.silence else "")
            latency = registry.adapter_latency(b) if b.timing != "ideal" else registry.ADAPTER_LATENCY[proto.medium]
            turnaround_of = getattr(rig.world.buses.get(name), "turnaround", None)
            last: dict[int | None, TraceRecord] = {}
            replies = 0
            overhead = 0.0
            for r in mine:  # each reply: its drive's turnaround (as the twin's bus gives it) and the adapter's latency
                if r.direction == "tx":
                    last[r.node] = r
                    continue
                if r.meaning.startswith("unsolicited"):
                    continue
                replies += 1
                turnaround = None
                request = last.get(r.node)
                if callable(turnaround_of) and request is not None:
                    turnaround = turnaround_of(request.data if request.ident is None else _can_frame(request))
                if turnaround is None:
                    c = on_bus.get(r.node) if r.node is not None else None
                    turnaround = registry.family(c.device).config_profile(c).turnaround if c is not None else 0.0
                overhead += turnaround + latency
            out.append(BusPlan(name, b.protocol, line, len(on_bus), len(mine), sum(sizes), load, replies, overhead))
        return out


def run(*, quick: bool = False, config: str | None = None, rate: float | None = None, speed: bool = True,
        out: Callable[[str], None] = print) -> list[Row]:
    """Run every benchmark and (``config``) the bus planner; print, and return the rows.
    ``quick``: tiny sizes (tests); ``speed=False``: the planner only."""
    if not speed:
        if config is not None:
            _print_plan(config, rate, out)
        return []
    core, cores = pin_one_core()
    try:
        return _run(quick, config, rate, out, core)
    finally:
        if cores is not None:
            os.sched_setaffinity(0, cores)


def _run(quick: bool, config: str | None, rate: float | None, out: Callable[[str], None],
         core: int | None) -> list[Row]:
    steps, raw_steps, repeats, min_time = (20, 500, 1, 0.01) if quick else (500, 20000, 5, 0.2)
    out(f"Python {platform.python_version()} on {platform.machine()}; pinned to core {core}; env rows the median of {repeats} "
        f"pairs (env block, reference), world and codec rows the best of {repeats}; "
        f"raw reference {raw_steps} mj_step on a fresh MjData")
    rows = list(env_rows(steps=steps, raw_steps=raw_steps, repeats=repeats))
    rows.append(world_row(raw_steps=raw_steps, repeats=repeats))
    rows.append(codec_row(repeats=repeats, min_time=min_time))
    rows += batched_rows(steps=steps * 4, raw_steps=raw_steps, repeats=repeats)
    out(table(rows))
    if config is not None:
        _print_plan(config, rate, out)
    return rows


def _print_plan(config: Any, rate: float | None, out: Callable[[str], None]) -> None:
    r = rate or PLAN_RATE
    out(f"\nBus planner for {config} (one control cycle = a command and a state read per joint, as measured on "
        f"its twins; wire time with worst-case CAN stuffing, Modbus t3.5; plus each transaction's drive turnaround "
        f"and adapter latency):")
    for p in plan(config, r):
        out("- " + p.text(r))


def table(rows: Sequence[Row]) -> str:
    """The rows as the issue's markdown table, details below."""
    lines = ["| measure | ratio | goal | |", "|---|---|---|---|"]
    lines += ["| " + " | ".join(r.cells()) + " |" for r in rows]
    lines.append("")
    lines += [f"- {r.measure}: {r.detail}" for r in rows if r.detail]
    return "\n".join(lines)


# -- the real bus: round trips of read-only transactions (joints bench --hardware) ------------------

#: rounds of every transaction measured per bus (the report gives medians)
HARDWARE_ROUNDS = 50
#: s of quiet before each measured transaction (the line settles; t3.5 and more)
HARDWARE_GAP = 0.004
#: ms above which a USB-serial adapter's latency timer gets a warning
LATENCY_TIMER_MAX_MS = 1


@dataclass
class Probe:
    """One read-only transaction of a bus, as ``rig.read_states()`` sends it: a request and its reply frames."""

    node: int | None  #: the drive's address / node id
    request: bytes
    ident: int | None  #: CAN identifier of the request (None on a byte stream)
    replies: list[tuple[int | None, bytes]]  #: the reply frames (CAN identifier, data)


@dataclass
class BusTimingReport:
    """What ``joints bench --hardware`` measured on one bus: per transaction of ``rig.read_states()``."""

    bus: str
    protocol: str
    line: str
    joints: dict[int | None, list[str]]  #: node -> the joints it serves
    probes: list[Probe]  #: the transactions measured
    wires: list[float]  #: wire time of each transaction [s]
    trips: list[list[float]]  #: measured round trips of each transaction [s]
    failures: int = 0
    warnings: list[str] | None = None

    def nodes(self) -> list[int | None]:
        """The drives measured (each once, in bus order)."""
        return list(dict.fromkeys(p.node for p, t in zip(self.probes, self.trips) if t))

    def round_trips(self, node: int | None) -> list[float]:
        return [x for p, t in zip(self.probes, self.trips) if p.node == node for x in t]

    def wire(self, node: int | None) -> float:
        """Median wire time of the drive's transactions [s]."""
        return _median([w for p, w in zip(self.probes, self.wires) if p.node == node])

    def overhead(self, node: int | None, quantile: float = 0.5) -> float:
        """Round trip minus wire time over the drive's transactions [s]: turnaround + adapter latency; the median,
        or another ``quantile`` (a low one is what the bus takes when the host is not held up itself)."""
        values = sorted(x - w for p, w, t in zip(self.probes, self.wires, self.trips) if p.node == node for x in t)
        if quantile == 0.5 or not values:
            return _median(values)
        return values[min(len(values) - 1, int(quantile * len(values)))]

    def adapter_latency(self, turnarounds: dict[int | None, float]) -> float:
        """The bus's adapter latency under the documented split: the median over its drives of the
        overhead minus the drive's own turnaround (its profile's), at least 0."""
        nodes = self.nodes()
        return max(0.0, _median([self.overhead(n) - turnarounds.get(n, 0.0) for n in nodes])) if nodes else 0.0


def _median(values: Sequence[float]) -> float:
    s = sorted(values)
    n = len(s)
    return (s[n // 2] if n % 2 else 0.5 * (s[n // 2 - 1] + s[n // 2])) if n else math.nan


def latency_timer(port: str, sys_root: Any = None) -> tuple[int, Any] | None:
    """The Linux USB-serial latency timer [ms] of serial ``port`` and its sysfs file, or None where it has none
    (``sys_root``: the sysfs mount, ``/sys`` by default; tests pass a fake tree)."""
    from pathlib import Path

    root = Path("/sys") if sys_root is None else Path(sys_root)
    tty = Path(os.path.realpath(port)).name
    path = root / "bus" / "usb-serial" / "devices" / tty / "latency_timer"
    try:
        return int(path.read_text().strip()), path
    except (OSError, ValueError):
        return None


def latency_warning(bus: str, port: str, ms: int, path: Any) -> str:
    """The warning for a latency timer above :data:`LATENCY_TIMER_MAX_MS`, with the ways to lower it."""
    tty = os.path.basename(os.path.realpath(port))
    return (f"bus {bus}: the USB-serial latency timer of {port} is {ms} ms ({path}): the adapter may hold every "
            f"reply up to {ms} ms before the host sees it. Lower it to 1 ms: `echo 1 | sudo tee {path}` (until the "
            f"adapter is plugged again), or for good with a udev rule (/etc/udev/rules.d/99-usb-serial-latency.rules: "
            f'ACTION=="add", SUBSYSTEM=="usb-serial", DRIVER=="ftdi_sio", ATTR{{latency_timer}}="1"), or '
            f"`setserial /dev/{tty} low_latency`")


def _probes(rig: Any) -> dict[str, list[Probe]]:
    """The transactions of one ``rig.read_states()`` per bus (read-only: status and position reads)."""
    from joints.link.trace import TraceRecord

    rig.read_states()  # first contact (a driver may learn the drive's firmware): not recorded
    records: list[TraceRecord] = []
    rig.trace(records.append)
    try:
        rig.read_states()
    finally:
        rig.trace(None)
    out: dict[str, list[Probe]] = {}
    for name, bus in rig.buses.items():
        mine = [r for r in records if r.bus == bus.link.name]
        probes: list[Probe] = []
        for r in mine:
            if r.direction == "tx":
                probes.append(Probe(r.node, bytes(r.data), r.ident, []))
            elif probes:
                probes[-1].replies.append((r.ident, bytes(r.data)))
        out[name] = [p for p in probes if p.replies]
    return out


def _serial_round_trips(bcfg: Any, probes: Sequence[Probe], rounds: int, gap: float) -> tuple[list[list[float]], int]:
    """Round trips over the serial port: write the request, time until every byte of the reply is in."""
    try:
        import serial
    except ImportError as exc:  # pragma: no cover - depends on the install
        from joints.errors import MissingDependencyError

        raise MissingDependencyError("pyserial", "serial") from exc
    out: list[list[float]] = [[] for _ in probes]
    failures = 0
    with serial.Serial(bcfg.port, bcfg.baudrate, parity=bcfg.parity, stopbits=bcfg.stopbits,
                       timeout=bcfg.timeout, exclusive=True) as ser:
        for _ in range(rounds):
            for i, p in enumerate(probes):
                expect = sum(len(d) for _i, d in p.replies) + (len(p.request) if bcfg.echo else 0)
                time.sleep(gap)
                ser.reset_input_buffer()
                t = time.perf_counter()
                ser.write(p.request)
                got = ser.read(expect)
                took = time.perf_counter() - t
                if len(got) == expect:
                    out[i].append(took)
                else:
                    failures += 1
    return out, failures


def _can_round_trips(transport: Any, probes: Sequence[Probe], rounds: int, gap: float,
                     timeout: float) -> tuple[list[list[float]], int]:
    """Round trips over the CAN transport: send the request frame, time until its reply frames are in."""
    import can

    out: list[list[float]] = [[] for _ in probes]
    failures = 0
    for _ in range(rounds):
        for i, p in enumerate(probes):
            assert p.ident is not None
            frame = can.Message(arbitration_id=p.ident, data=p.request, is_extended_id=p.ident > 0x7FF)
            wanted = [i for i, _d in p.replies]
            time.sleep(gap)
            while transport.recv(0.0) is not None:  # stale frames (heartbeats) out of the way
                pass
            t = time.perf_counter()
            transport.send(frame)
            end = t + timeout
            while wanted:
                got = transport.recv(max(0.0, end - time.perf_counter()))
                if got is None:
                    break
                if got.arbitration_id in wanted:
                    wanted.remove(got.arbitration_id)
            took = time.perf_counter() - t
            if wanted:
                failures += 1
            else:
                out[i].append(took)
    return out, failures


def _wire(timing: Any, probe: Probe) -> float:
    """Wire time of one transaction: request (+ t3.5 on Modbus RTU) + reply frames."""
    if timing.medium == "can":
        import can

        def frame(ident: int | None, data: bytes) -> Any:
            return can.Message(arbitration_id=ident or 0, data=data, is_extended_id=(ident or 0) > 0x7FF)

        return float(timing.frame_time(frame(probe.ident, probe.request)) + sum(
            timing.frame_time(frame(i, d)) for i, d in probe.replies))
    return float(timing.bytes_time(len(probe.request)) + timing.silence
                 + timing.bytes_time(sum(len(d) for _i, d in probe.replies)))


def measure_hardware(config: Any, *, rounds: int = HARDWARE_ROUNDS, gap: float = HARDWARE_GAP,
                     sys_root: Any = None) -> list[BusTimingReport]:
    """Round trips of every drive's read-only status transaction on the real buses of ``config``.

    Opens the config on the hardware backend, enables nothing and writes nothing (``on_exit`` is
    forced to ``"none"``): the transactions are those of ``rig.read_states()``, replayed byte for
    byte (frame for frame) ``rounds`` times each, ``gap`` s apart.
    """
    from dataclasses import replace as _replace

    import joints
    from joints.config import RigConfig, load, parse
    from joints.rig import served_timing

    if isinstance(config, RigConfig):
        cfg = config.with_backend("hardware")
    elif isinstance(config, dict):
        cfg = parse(config, backend="hardware")
    else:
        cfg = load(config, backend="hardware")
    cfg = _replace(cfg, on_exit="none")  # read only: never disable (or stop) a drive on the way out
    timings = served_timing(cfg.with_backend("sim"))
    reports: list[BusTimingReport] = []
    rig = joints.open(cfg)
    serial_probes: dict[str, list[Probe]] = {}
    try:
        probes = _probes(rig)
        for name, b in cfg.buses.items():
            warnings: list[str] = []
            timing = timings[name]
            nodes: dict[int | None, list[str]] = {}
            for jn, j in cfg.joints.items():
                if j.bus == name:
                    nodes.setdefault(j.address, []).append(jn)
            if timing.medium == "can":
                line = f"{b.bitrate} bit/s"
                trips, failures = _can_round_trips(rig.buses[name].transport, probes[name], rounds, gap, b.timeout)
            else:
                line = f"{b.baudrate} baud 8{b.parity}{b.stopbits}" + (", t3.5" if timing.silence else "")
                serial_probes[name] = probes[name]
                trips, failures = [], 0
                found = latency_timer(b.port or "", sys_root)
                if found is not None and found[0] > LATENCY_TIMER_MAX_MS:
                    warnings.append(latency_warning(name, b.port or "", found[0], found[1]))
            reports.append(BusTimingReport(name, b.protocol, line, nodes, probes[name],
                                           [_wire(timing, p) for p in probes[name]], trips, failures, warnings))
    finally:
        rig.close()  # the serial ports are measured on their own, after the rig let them go
    for report in reports:
        if report.bus in serial_probes:
            report.trips, report.failures = _serial_round_trips(cfg.buses[report.bus],
                                                                      serial_probes[report.bus], rounds, gap)
    return reports


def profile_turnarounds(config: Any) -> dict[str, dict[int | None, float]]:
    """Per bus, per drive address: the turnaround its profile states (the split's assumption)."""
    from joints.config import RigConfig, load
    from joints.rig import served_timing

    cfg = config if isinstance(config, RigConfig) else load(config, backend="sim")
    return {name: dict(t.turnarounds) for name, t in served_timing(cfg.with_backend("sim")).items()}


def overlay_text(reports: Sequence[BusTimingReport], turnarounds: dict[str, dict[int | None, float]], *,
                 source: str = "", per_joint: bool = True) -> str:
    """The measured timing as a config overlay (TOML; ``timing_overlay = "FILE"`` in a config uses it).

    The split (from the host only the sum is seen): each drive keeps the turnaround its profile
    states; the bus's ``adapter_latency`` is the median over its drives of the measured overhead
    minus that turnaround; each joint's ``profile.turnaround`` is then its drive's overhead minus
    the bus's adapter latency (so every drive's sum is the measured one). ``per_joint=False``
    (profiles without a ``turnaround`` field) writes the adapter latency only.
    """
    lines = [(f"# measured by `joints bench --hardware`{' on ' + source if source else ''}: per transaction, the "
              "overhead (round trip - wire time) = turnaround + adapter_latency;"),
             "# split: drives keep their profile's turnaround, the bus gets the median rest (docs/hardware-timing.md)",
             ""]
    joint_lines: list[str] = []
    for r in reports:
        nodes = r.nodes()
        if not nodes:
            continue
        latency = r.adapter_latency(turnarounds.get(r.bus, {}))
        lines += [f"[buses.{r.bus}]", f"adapter_latency = {latency:.6f}", ""]
        if per_joint:
            for n in nodes:
                turn = max(0.0, r.overhead(n) - latency)
                for jn in r.joints.get(n, []):
                    joint_lines += [f"[joints.{jn}.profile]", f"turnaround = {turn:.6f}", ""]
    return "\n".join(lines + joint_lines)


def _has_turnaround(cfg: Any, joint: str) -> bool:
    """Whether the joint's device profile has a ``turnaround`` a config may override."""
    import dataclasses

    from joints import registry

    j = cfg.joints[joint]
    prof = registry.family(j.device).config_profile(j)
    return "turnaround" in {f.name for f in dataclasses.fields(prof)}


def hardware_report(reports: Sequence[BusTimingReport]) -> str:
    """The measurements as text: per bus and drive, round trip, wire time and overhead per transaction."""
    out: list[str] = []
    for r in reports:
        out.append(f"bus {r.bus} ({r.protocol}, {r.line}):")
        if not r.nodes():
            out.append(f"- no complete reply in {r.failures} tries")
        for n in r.nodes():
            who = ", ".join(r.joints.get(n, [])) or f"node {n}"
            s = sorted(r.round_trips(n))
            out.append(f"- {who}: round trip median {_median(s) * 1e3:.3f} ms (p10 {s[len(s) // 10] * 1e3:.3f}, "
                       f"p90 {s[(9 * len(s)) // 10] * 1e3:.3f}; {len(s)} transactions), wire {r.wire(n) * 1e3:.3f} ms "
                       f"-> overhead {r.overhead(n) * 1e3:.3f} ms per transaction (turnaround + adapter latency)")
        if r.nodes():
            every = sorted(x - w for w, t in zip(r.wires, r.trips) for x in t)
            out.append(f"- the bus: overhead {_median(every) * 1e3:.3f} ms per transaction (median of all "
                       f"{len(every)}; turnaround + adapter latency)")
        if r.failures:
            out.append(f"- {r.failures} transaction(s) without a complete reply (not counted)")
        out += [f"WARNING: {w}" for w in r.warnings or []]
    return "\n".join(out)


def run_hardware(config: str, *, overlay: str | None = None, rounds: int = HARDWARE_ROUNDS, sys_root: Any = None,
                 out: Callable[[str], None] = print) -> list[BusTimingReport]:
    """``joints bench --hardware``: measure, print, and (``overlay``) write the timing overlay file."""
    from pathlib import Path

    from joints.config import load

    reports = measure_hardware(config, rounds=rounds, sys_root=sys_root)
    out(f"Round trips of read-only transactions on the buses of {config} ({rounds} each, medians):")
    out(hardware_report(reports))
    if overlay is not None:
        cfg = load(config, backend="sim")
        per_joint = all(_has_turnaround(cfg, name) for name in cfg.joints)
        Path(overlay).write_text(overlay_text(reports, profile_turnarounds(cfg), source=str(config),
                                              per_joint=per_joint), encoding="utf-8")
        out(f"wrote {overlay}: add `timing_overlay = \"{overlay}\"` to the config for the twins to use it")
    return reports
