"""The batched step of N :class:`~envs.base.JointsEnv` rigs: the single env's per-step Python as array operations.

Rule: a rig gets the bits its own ``begin_step`` / ``finish_step`` would give it - the same IEEE operations on
the same values, only across the rigs at once (the action's checks and clip, the commands and their limits,
the velocity braking cap, the observation and its bounds, the termination, the info's arrays). What stays rig
by rig is each rig's own I/O (its compiled path's command and state calls), a task's rule that is not written
across rigs (the arm's shield; task terms and rewards of a task without :meth:`~envs.base.JointsEnv._batch_task`)
and a reward's ``np.dot`` over several joints. The batched path is taken only in the steady case - every rig
acting, open and observed once, on the compiled path, without a human render - and is declined
(:meth:`Batch.begin` returns False) before anything is sent otherwise; a step that ends a rig's episode (a fault,
a limit violation) gets each rig's outcome from the single env's own code.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

import joints
from envs.base import JointsEnv, braking_speed

__all__ = ["WRITTEN_ACROSS", "Batch"]

#: JointsEnv's methods whose work :class:`Batch` does across the rigs: a type that replaces one is stepped rig by rig
WRITTEN_ACROSS = ("begin_step", "finish_step", "_finish", "_read", "_observation", "_command", "_commands", "_limit",
                  "_safe", "tick_time", "note_overrun")


def _max(x: np.ndarray, low: np.ndarray) -> np.ndarray:
    """``max(x, low)`` element by element as Python's ``max`` has it: ``low`` only where ``low > x``."""
    out: np.ndarray = np.where(low > x, low, x)
    return out


def _min(x: np.ndarray, high: np.ndarray) -> np.ndarray:
    """``min(x, high)`` as Python's ``min``: ``high`` only where ``high < x``."""
    out: np.ndarray = np.where(high < x, high, x)
    return out


class Batch:
    """The rigs ``envs`` (one :class:`~envs.base.JointsEnv` type, same joints, spaces and action mode) stepped by
    array operations; :meth:`of` says whether they can be."""

    def __init__(self, envs: Sequence[JointsEnv]) -> None:
        self.envs = list(envs)
        first = self.envs[0]
        self.kind = type(first)
        self.mode = first.action_mode
        self.n = len(first.joints)
        self.names = list(first.joint_names)
        #: the single env's fixed bounds, one row per rig (set at construction, never changed)
        self.pos_lo = np.array([e._pos_lo for e in self.envs])
        self.pos_hi = np.array([e._pos_hi for e in self.envs])
        self.span = self.pos_hi - self.pos_lo
        self.torque = np.array([e._torque_list for e in self.envs])
        self.inset_lo = np.array([e._inset_lo for e in self.envs])
        self.inset_hi = np.array([e._inset_hi for e in self.envs])
        self.lo_stop = np.array([e._lo_list for e in self.envs])
        self.hi_stop = np.array([e._hi_list for e in self.envs])
        self.obs_low = np.array([e._obs_low for e in self.envs])
        self.obs_high = np.array([e._obs_high for e in self.envs])
        self.shielded = self.kind._shield is not JointsEnv._shield
        self.task = self.kind._batch_task is not JointsEnv._batch_task
        self.taken = 0  #: steps the batched path took (begin to finish)
        #: every rig's commands in one compiled call, and every rig's state read in another, where every rig is a
        #: rig of eRobs on one-call exchanges (:class:`joints.compiled_path.CompiledRigs`; None: rig by rig)
        self.paths = [e.compiled_path for e in self.envs]
        self.rigs = joints.CompiledRigs.build(self.paths)
        #: whether these rigs' paths can take an env's whole step in one call and the type keeps the step's parts
        #: (as ``JointsEnv.step`` asks: fixed for the paths the batch was built with, :meth:`_rigs`)
        self._stepping = all(p is not None and p.steps for p in self.paths) and first._keeps_step_parts(JointsEnv)
        #: the step under way: (actions, commands, actions as lists, the rigs' one call or None), begin to finish
        #: and every rig's states where the one call was the whole step (:meth:`waited`)
        self._pending: tuple[np.ndarray, np.ndarray, list[list[float]], joints.CompiledRigs | None,
                             list[list[joints.JointState]] | None] | None = None

    @classmethod
    def of(cls, envs: Sequence[Any]) -> Batch | None:
        """The batch of ``envs``, or None where their step cannot be written across them (not all one
        :class:`~envs.base.JointsEnv` type in sim with a compiled path, different joints or action modes, a type
        that replaces a method of the step this module writes across the rigs)."""
        first = envs[0]
        kind = type(first)
        if not issubclass(kind, JointsEnv) or not first.sim \
                or any(getattr(kind, name) is not getattr(JointsEnv, name) for name in WRITTEN_ACROSS):
            return None
        for e in envs:
            if type(e) is not kind or not e.sim or e.compiled_path is None or e.render_mode == "human" \
                    or e.action_mode != first.action_mode or e.joint_names != first.joint_names \
                    or e._obs_dim != first._obs_dim:
                return None
        return cls(envs)

    # -- begin: every rig's action checked, clipped, made safe and sent --------------------------------------
    def begin(self, actions: np.ndarray) -> bool:
        """Every rig's ``begin_step`` (same checks, same commands, same bits); False, with nothing sent, where a
        rig's own ``begin_step`` must run (an action of the wrong shape or not finite: its error, in its
        order; a closed rig; a rig whose action mode or render mode was changed since)."""
        envs = self.envs
        a = np.asarray(actions, dtype=np.float64)
        if a.shape != (len(envs), self.n) or not np.isfinite(a).all():
            return False
        queued = []
        mode = self.mode
        for i, e in enumerate(envs):
            if e._closed or not e._states or e.action_mode != mode or e.render_mode == "human":
                return False
            if e._queue:
                queued.append((i, e._queue))
        a = np.maximum(a, -1.0)  # begin_step's clip of a finite value (no bound is a signed zero): the same bits
        np.minimum(a, 1.0, out=a)
        sent = a
        if queued:  # bus latency (domain randomisation): a rig's action waits its turn, an older one is sent
            sent = a.copy()
            for i, q in queued:
                q.append(a[i])
                sent[i] = q.popleft()
        if mode == "position":  # _commands: clip(lo + (v + 1) / 2 * (hi - lo), lo, hi)
            lo = self.pos_lo
            c = _min(_max(lo + (sent + 1.0) * 0.5 * self.span, lo), self.pos_hi)
        elif mode == "torque":  # _commands, then _limit's clip
            m = self.torque
            c = _min(_max(sent * m, -m), m)
        else:
            c = self._velocity(sent)
        if self.shielded and mode != "torque":  # _safe: the task's rule on position and velocity commands
            rows = c.tolist()
            for i, e in enumerate(envs):
                rows[i] = e._shield(rows[i])
            c = np.array(rows)
        else:
            rows = c.tolist()
        skips = [[not j.enabled for j in e.joints] for e in envs]
        rigs = self._rigs()
        read: list[list[joints.JointState]] | None = None
        if rigs is not None and self._whole(skips):  # every rig's whole step in one call (as JointsEnv.step's)
            got = rigs.step(mode, rows, [e.tick_time(1) for e in envs], [e.rig for e in envs])
            if got is not None:
                read = []
                for i, e in enumerate(envs):
                    e._sent = c[i]
                    e._tick += 1
                    states, remaining = got[i]
                    e.note_overrun(-remaining)
                    e._states = states
                    read.append(states)
        if read is None:  # every rig's commands in one call, else each rig's own
            carried = rigs is not None and rigs.command(mode, rows, skips)
            for i, e in enumerate(envs):
                e._sent = c[i]
                if not carried:
                    e.compiled_path.command(mode, rows[i], skips[i])  # type: ignore[union-attr]
                e._tick += 1
        # (no rig's path can change before finish: the vector step's own)
        self._pending = (a, c, a.tolist(), rigs, read)
        return True

    def _whole(self, skips: list[list[bool]]) -> bool:
        """Whether every rig's step may go whole (commands, the wait for the tick, the reads) in one call, as
        ``JointsEnv.step`` takes its own one-call step: the paths able (:attr:`_stepping`), every joint commanded,
        no overrun raised."""
        if not self._stepping:
            return False
        for e, skip in zip(self.envs, skips):
            if e.raise_on_overrun or True in skip:
                return False
        return True

    @property
    def waited(self) -> bool:
        """Whether the step under way (begin to finish) already waited for every rig's tick (its one call)."""
        return self._pending is not None and self._pending[4] is not None

    def _rigs(self) -> joints.CompiledRigs | None:
        """The rigs' one call (:attr:`rigs`) while every rig keeps the compiled path it was built with."""
        rigs = self.rigs
        if rigs is None:
            return None
        for e, p in zip(self.envs, self.paths):
            if e.compiled_path is not p:
                return None
        return rigs

    def joined(self) -> bool:
        """Whether the rigs' state read goes in one call that may run their sleeps too
        (:meth:`joints.CompiledRigs.joined`): the one call of the step under way, else :meth:`_rigs`."""
        rigs = self._rigs() if self._pending is None else self._pending[3]
        return rigs is not None and rigs.joined()

    def _velocity(self, a: np.ndarray) -> np.ndarray:
        """Velocity commands: ``_commands``, ``_limit``'s clip to the speed cap, the braking cap of ``_safe``."""
        envs = self.envs
        cap = np.array([e.speed_cap for e in envs])
        v = np.array([e._vel_list for e in envs])
        c = _min(_max(a * v, -cap), cap)
        states = [e._states for e in envs]
        p = np.array([[s.position for s in st] for st in states])
        u = np.array([[s.velocity for s in st] for st in states])
        acc = np.array([e.profile_acceleration for e in envs])
        dt = np.array([[e.control_period + e.bus_lag] for e in envs])
        low = -braking_speed(p - self.inset_lo, acc, dt, -u)  # type: ignore[arg-type]
        high = braking_speed(self.inset_hi - p, acc, dt, u)  # type: ignore[arg-type]
        m = np.where(c > low, c, low)  # clip_to: numpy's clip between array bounds
        out: np.ndarray = np.where(m < high, m, high)
        return out

    # -- finish: every rig read, observed, rewarded -----------------------------------------------------------
    def finish(self) -> tuple[np.ndarray, np.ndarray, dict[str, Any]] | list[tuple[Any, ...]]:
        """Every rig's ``finish_step``: (observations, rewards, the batch's info arrays) where no rig's episode
        ended, else each rig's own outcome (obs, reward, terminated, truncated, info), from its own code."""
        assert self._pending is not None
        a, c, values, rigs, read = self._pending  # the one call that sent this step's commands, or None
        self._pending = None
        envs = self.envs
        n = self.n
        if read is None and rigs is not None:  # every rig's in one call (unless the step's one call read them)
            read = rigs.states()
            if read is not None:
                for e, st in zip(envs, read):
                    e._states = st
        states = [e._read() for e in envs] if read is None else read
        flat = [s for st in states for s in st]
        p = np.array([s.position for s in flat]).reshape(len(envs), n)
        if any(s.fault is not None for s in flat) \
                or ((p < self.lo_stop) | (p > self.hi_stop)).any():  # an episode ends: each rig on its own
            return [e._finish((a[i], values[i]), states[i]) for i, e in enumerate(envs)]
        self.taken += 1
        if n == 1:  # np.dot of one difference is its square
            d = a[:, 0] - np.array([e._prev_values[0] for e in envs])
            change = d * d
        else:  # each rig's np.dot, on its own difference array
            diffs = [a[i] - e._prev_action for i, e in enumerate(envs)]
            change = np.array([float(np.dot(d, d)) for d in diffs])
        obs = np.empty((len(envs), self.obs_low.shape[1]))
        obs[:, :n] = p
        obs[:, n:2 * n] = np.array([s.velocity for s in flat]).reshape(len(envs), n)
        obs[:, 2 * n:3 * n] = np.array([s.torque for s in flat]).reshape(len(envs), n)
        info_terms: dict[str, np.ndarray] | None
        term_dicts: list[dict[str, Any]] = []
        if self.task:
            reward, info_terms = self.kind._batch_task(envs, p, change, obs[:, 3 * n:])
        else:
            positions = p.tolist()
            rows, rewards = [], []
            for i, e in enumerate(envs):
                rows.append(e._task_terms(positions[i]))
                r, t = e._reward(positions[i], float(change[i]))
                rewards.append(float(r))
                term_dicts.append(t)
            if obs.shape[1] > 3 * n:
                obs[:, 3 * n:] = np.array(rows)
            reward = np.array(rewards)
            info_terms = _info_arrays(term_dicts)
        for i, e in enumerate(envs):
            if e._noise_rng is not None and e._noisy:
                obs[i, :n] += e._noise_rng.normal(0.0, 1.0, n) * e._noise
            e._prev_action, e._prev_values = a[i], values[i]
        np.maximum(obs, self.obs_low, out=obs)
        np.minimum(obs, self.obs_high, out=obs)
        if info_terms is None:  # terms of different keys or types: the rigs' own infos
            return self._outcomes(obs, reward, term_dicts)
        times = [float(e.rig.time) for e in envs]
        overruns = [e._overrun for e in envs]
        if {type(x) for x in overruns} != {float}:  # typed otherwise: the rigs' own infos (as _add_info types them)
            columns = {key: value.tolist() for key, value in info_terms.items()}
            per_rig = [{key: column[i] for key, column in columns.items()} for i in range(len(envs))]
            return self._outcomes(obs, reward, per_rig)
        count = len(envs)
        every = np.ones(count, dtype=np.bool_)
        faults: dict[str, Any] = {}
        for name in self.names:
            faults[name] = np.full(count, fill_value=None, dtype=object)
            faults["_" + name] = every.copy()
        info: dict[str, Any] = {"time": np.array(times, dtype=float), "_time": every.copy(),
                                "overrun": np.array(overruns, dtype=float), "_overrun": every.copy(),
                                "faults": faults, "_faults": every.copy()}
        for key, value in info_terms.items():
            info[key] = value
            info["_" + key] = every.copy()
        info["limit_violation"] = np.zeros(count, dtype=bool)
        info["_limit_violation"] = every.copy()
        info["command"] = c.copy()
        info["_command"] = every.copy()
        return obs, reward, info

    def _outcomes(self, obs: np.ndarray, reward: np.ndarray, terms: list[dict[str, Any]]) -> list[tuple[Any, ...]]:
        """Each rig's outcome (obs, reward, terminated, truncated, info) of a step that ended no episode, from
        the batch's arrays, each info as ``_finish`` makes it (``terms``: each rig's reward terms)."""
        out = []
        for i, e in enumerate(self.envs):
            info = {"time": float(e.rig.time), "overrun": e._overrun, "faults": dict.fromkeys(self.names)}
            info.update(terms[i])
            info["limit_violation"] = False
            info["command"] = e._sent
            out.append((obs[i], float(reward[i]), False, False, info))
        return out


def _info_arrays(infos: Sequence[dict[str, Any]]) -> dict[str, np.ndarray] | None:
    """The batch's arrays of one flat info per rig (``JointsVectorEnv._batched_info``'s for plain numbers:
    one array per key of the type all rigs share), without masks; None where keys or types differ or a
    value is not a plain number."""
    keys = list(infos[0])
    for info in infos:
        if list(info) != keys:
            return None
    out: dict[str, np.ndarray] = {}
    for key in keys:
        if key.startswith("_") or key == "final_obs":
            return None
        values = [info[key] for info in infos]
        kind = type(values[0])
        if not (kind in (int, float, bool) or issubclass(kind, np.number)):
            return None
        for v in values:
            if type(v) is not kind:
                return None
        out[key] = np.array(values, dtype=kind)
    return out
