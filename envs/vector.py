"""Batched rigs: N copies of a ``joints/`` env in one process, behind gymnasium's vector API.

Rule: the batched env is N single envs (each its own rig, MuJoCo model and data - so domain
randomisation still differs per rig - and its own ``np_random``) that act, then wait for their
next control tick TOGETHER (:func:`joints.sleep_together`: every drive of every rig and every
rig's physics run in one compiled call), then observe. Everything else is the single env's own
code, so the results are those of gymnasium's ``SyncVectorEnv`` over ``gym.make(id)`` envs with
the same seeds: spaces, observations, rewards, terminations, truncations (the registered
``max_episode_steps``, as ``TimeLimit``), infos and autoreset as gymnasium 1.x defines it
(:class:`gymnasium.vector.AutoresetMode`: ``NEXT_STEP`` by default, ``SAME_STEP``, ``DISABLED``).

>>> import gymnasium as gym, envs
>>> vec = gym.make_vec("joints/ErobReach-v0", num_envs=16, vectorization_mode="vector_entry_point")  # doctest: +SKIP
>>> vec = envs.make_vector_env("joints/ErobReach-v0", num_envs=16, domain_randomization=True)  # doctest: +SKIP

An env type that cannot split its step (no ``batchable`` act / outcome) is stepped one by one.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

import joints
from envs.batch import Batch

__all__ = ["JointsVectorEnv", "make_vector_env", "vector_entry_point"]


#: rigs from which a batch takes the batched path by default (:attr:`JointsVectorEnv.batched`) where no compiled call
#: carries its rigs' steps (with one, from one rig on)
BATCH_MIN = 4


def _load(entry_point: str | Callable[..., gym.Env[Any, Any]]) -> Callable[..., gym.Env[Any, Any]]:
    if callable(entry_point):
        return entry_point
    module, _, name = entry_point.partition(":")
    made: Callable[..., gym.Env[Any, Any]] = getattr(importlib.import_module(module), name)
    return made


def _wait_together(envs: Sequence[Any], own: bool = False) -> None:
    """Each of ``envs`` waits for its tick (as ``RigEnv._wait_until``: an overrun noted), the rigs that must sleep
    together in one call; ``own``: each rig sleeps its own sleep (a world that books its sleeps: the batch's state
    read runs them, every rig's in one call - :meth:`joints.CompiledRigs.joined`)."""
    rigs: list[joints.Rig] = []
    spans: list[float] = []
    for env in envs:
        rig = env.rig
        remaining = env.tick_time() - rig.time
        if remaining > 0:
            rigs.append(rig)
            spans.append(remaining)
        env.note_overrun(-remaining)
    if rigs and own:
        for rig, span in zip(rigs, spans):
            rig.sleep(span)
    elif rigs:
        joints.sleep_together(rigs, spans)


class JointsVectorEnv(VectorEnv[Any, Any, Any]):
    """``num_envs`` rigs of one env type in this process, stepped together (see the module docstring).

    Args:
        env: the single env's class (or ``"module:Class"``), made ``num_envs`` times with ``kwargs``.
        num_envs: rigs.
        max_episode_steps: truncation after this many steps of an episode (``None``: never).
        autoreset_mode: gymnasium's :class:`~gymnasium.vector.AutoresetMode`.
        kwargs: the single env's arguments (config, action_mode, domain_randomization ...).
    """

    metadata: dict[str, Any] = {"autoreset_mode": AutoresetMode.NEXT_STEP, "render_modes": ["rgb_array"]}  # noqa: RUF012

    def __init__(self, env: str | Callable[..., gym.Env[Any, Any]], num_envs: int, *,
                 max_episode_steps: int | None = None,
                 autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP, **kwargs: Any) -> None:
        self.envs: list[Any] = []  # first: close() (gymnasium calls it from __del__) works on a half-built env
        if isinstance(num_envs, bool) or not isinstance(num_envs, int) or num_envs < 1:
            raise ValueError(f"num_envs must be an integer >= 1, got {num_envs!r}")
        if max_episode_steps is not None and (not isinstance(max_episode_steps, int) or max_episode_steps < 1):
            raise ValueError(f"max_episode_steps must be an integer >= 1 or None, got {max_episode_steps!r}")
        self.autoreset_mode = AutoresetMode(autoreset_mode)
        self.metadata = {**type(self).metadata, "autoreset_mode": self.autoreset_mode}
        make = _load(env)
        try:
            for _ in range(num_envs):
                self.envs.append(make(**kwargs))
        except BaseException:
            for e in self.envs:
                e.close()
            self.envs = []
            raise
        first = self.envs[0]
        self.num_envs = num_envs
        self.max_episode_steps = max_episode_steps
        self.render_mode = first.render_mode
        self.single_observation_space = first.observation_space
        self.single_action_space = first.action_space
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        self.action_space = batch_space(self.single_action_space, num_envs)
        for e in self.envs[1:]:
            if e.observation_space != self.single_observation_space or e.action_space != self.single_action_space:
                raise ValueError("the rigs of a batched env must have the same spaces")
        self._elapsed = np.zeros(num_envs, dtype=np.int64)
        self._autoreset = np.zeros(num_envs, dtype=np.bool_)
        self._obs: np.ndarray = np.zeros((num_envs, *self.single_observation_space.shape),  # type: ignore[misc]
                                         dtype=self.single_observation_space.dtype)
        self._has_reset = False
        self.closed = False
        #: the rigs' per-step Python across the batch (:mod:`envs.batch`), where their type allows it
        self._batch = Batch.of(self.envs)
        #: take the batched path where it can be taken (False: every step rig by rig, the reference); by
        #: default where one compiled call carries the rigs' steps (:class:`joints.CompiledRigs`: each step whole in
        #: one call, fewer calls than each rig's own from one rig on), else from BATCH_MIN rigs on (below, the
        #: batch's fixed cost of array calls exceeds what it saves)
        self.batched = num_envs >= BATCH_MIN or (self._batch is not None and self._batch.rigs is not None)

    # -- what a batch shares -------------------------------------------------------------------
    @property
    def models(self) -> list[Any]:
        """Each rig's MuJoCo model (sim)."""
        return [e.model for e in self.envs]

    @property
    def dt(self) -> float:
        """Seconds per step (every rig's control period)."""
        return float(self.envs[0].dt)

    # -- gymnasium vector API ------------------------------------------------------------------
    def reset(self, *, seed: int | Sequence[int | None] | None = None,
              options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        """As ``SyncVectorEnv.reset``: seeds ``seed + i`` (or one per rig), ``options["reset_mask"]``."""
        seeds: list[int | None]
        if seed is None:
            seeds = [None] * self.num_envs
        elif isinstance(seed, int):
            seeds = [seed + i for i in range(self.num_envs)]
        else:
            seeds = list(seed)
        if len(seeds) != self.num_envs:
            raise ValueError(f"If seeds are passed as a list the length must match num_envs={self.num_envs} "
                             f"but got length={len(seeds)}.")
        options = dict(options) if options is not None else None
        mask = np.ones(self.num_envs, dtype=np.bool_)
        if options is not None and "reset_mask" in options:
            mask = options.pop("reset_mask")
            if not isinstance(mask, np.ndarray) or mask.shape != (self.num_envs,) or mask.dtype != np.bool_ \
                    or not mask.any():
                raise ValueError(f"options['reset_mask'] must be a bool array of shape ({self.num_envs},) with a "
                                 f"True value, got {mask!r}")
            if not self._has_reset:
                raise gym.error.ResetNeeded("reset the whole batch before a masked reset")
        reset: list[tuple[int, dict[str, Any]]] = []
        for i, env in enumerate(self.envs):
            if mask[i]:
                self._obs[i], info = env.reset(seed=seeds[i], options=options)
                self._elapsed[i] = 0
                self._autoreset[i] = False
                reset.append((i, info))
        infos = self._batched_info([info for _, info in reset]) if len(reset) == self.num_envs else None
        if infos is None:
            infos = {}
            for i, info in reset:
                infos = self._add_info(infos, info, i)
        self._has_reset = True
        return self._obs.copy(), infos

    def step(self, actions: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """As ``SyncVectorEnv.step`` over ``TimeLimit`` envs; every rig that steps waits for its tick
        together with the others."""
        if not self._has_reset:
            raise gym.error.ResetNeeded("Cannot call env.step() before calling env.reset()")
        actions = np.asarray(actions)
        n = self.num_envs
        if actions.shape[:1] != (n,):
            raise ValueError(f"actions of shape {actions.shape}: expected {n} rows")
        if actions.dtype.kind == "f" and actions.dtype != np.float64:  # (exact, and what each rig casts its row to)
            actions = actions.astype(np.float64)
        batch = self._batch
        if batch is not None and self.batched and self.autoreset_mode is not AutoresetMode.SAME_STEP \
                and not self._autoreset.any() and batch.begin(actions):
            return self._step_batch(batch)
        rewards = np.zeros(n, dtype=np.float64)
        terminated = np.zeros(n, dtype=np.bool_)
        truncated = np.zeros(n, dtype=np.bool_)
        infos_of: list[dict[str, Any]] = [{} for _ in range(n)]
        finals: dict[int, tuple[Any, dict[str, Any]]] = {}
        acting: list[tuple[int, Any]] = []
        envs = self.envs
        mode = self.autoreset_mode
        pending = self._autoreset.tolist()
        obs_rows = self._obs
        for i, env in enumerate(envs):
            if pending[i] and mode is AutoresetMode.NEXT_STEP:
                obs_rows[i], infos_of[i] = env.reset()
                self._elapsed[i] = 0
            elif pending[i] and mode is AutoresetMode.DISABLED:
                raise gym.error.ResetNeeded(f"rig {i} ended its episode: reset it (autoreset is disabled)")
            elif env.batchable:
                acting.append((i, env.begin_step(actions[i])))
            else:  # an env that cannot split its step: on its own
                acting.append((i, None))
                obs, rewards[i], terminated[i], truncated[i], infos_of[i] = env.step(actions[i])
                obs_rows[i] = obs
        _wait_together([envs[i] for i, token in acting if token is not None and envs[i].batchable])
        limit = self.max_episode_steps
        elapsed = self._elapsed
        if mode is AutoresetMode.SAME_STEP:  # rig by rig: a rig that ends is reset at once
            for i, token in acting:
                env = envs[i]
                if env.batchable:
                    obs, rewards[i], terminated[i], truncated[i], infos_of[i] = env.finish_step(token)
                    obs_rows[i] = obs
                elapsed[i] += 1
                if limit is not None and elapsed[i] >= limit:
                    truncated[i] = True
                if terminated[i] or truncated[i]:
                    finals[i] = (obs_rows[i].copy(), infos_of[i])
                    obs_rows[i], infos_of[i] = env.reset()
                    elapsed[i] = 0
        elif acting:  # every rig's outcome, then each array at once
            done = [(i, envs[i].finish_step(token)) for i, token in acting if envs[i].batchable]
            if done:
                rows: Any = [i for i, _ in done]
                if len(rows) == n:  # every rig (in order): a slice, not a gather
                    rows = slice(None)
                obs_rows[rows] = [out[0] for _, out in done]
                rewards[rows] = [out[1] for _, out in done]
                terminated[rows] = [out[2] for _, out in done]
                truncated[rows] = [out[3] for _, out in done]
                for i, out in done:
                    infos_of[i] = out[4]
            stepped: Any = slice(None) if len(acting) == n else [i for i, _ in acting]
            elapsed[stepped] += 1
            if limit is not None:
                truncated[stepped] |= elapsed[stepped] >= limit
        infos = None if finals else self._batched_info(infos_of)
        if infos is None:
            infos = {}
            for i in range(n):
                if i in finals:
                    infos = self._add_info(infos, {"final_obs": finals[i][0], "final_info": finals[i][1]}, i)
                infos = self._add_info(infos, infos_of[i], i)
        self._autoreset = np.logical_or(terminated, truncated)
        return self._obs.copy(), rewards, terminated, truncated, infos

    @property
    def batched_steps(self) -> int:
        """Steps the batched path (:mod:`envs.batch`) took from the rigs' actions to the batch's arrays."""
        return 0 if self._batch is None else self._batch.taken

    def _step_batch(self, batch: Batch) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """:meth:`step` once ``batch`` sent every rig's commands (no rig was due for a reset)."""
        if not batch.waited:  # (the step's one call waited for every rig's tick)
            _wait_together(self.envs, batch.joined())
        out = batch.finish()
        n = self.num_envs
        if isinstance(out, tuple):  # the batch's arrays: no episode ended
            obs, rewards, infos = out
            self._obs[:] = obs
            terminated = np.zeros(n, dtype=np.bool_)
            truncated = np.zeros(n, dtype=np.bool_)
        else:  # each rig's outcome
            self._obs[:] = [o[0] for o in out]
            rewards = np.array([o[1] for o in out], dtype=np.float64)
            terminated = np.array([o[2] for o in out], dtype=np.bool_)
            truncated = np.array([o[3] for o in out], dtype=np.bool_)
            infos_of = [o[4] for o in out]
            got = self._batched_info(infos_of)
            if got is None:
                got = {}
                for i, info in enumerate(infos_of):
                    got = self._add_info(got, info, i)
            infos = got
        self._elapsed += 1
        if self.max_episode_steps is not None:
            truncated |= self._elapsed >= self.max_episode_steps
        self._autoreset = np.logical_or(terminated, truncated)
        return self._obs.copy(), rewards, terminated, truncated, infos

    def _batched_info(self, infos: Sequence[dict[str, Any]]) -> dict[str, Any] | None:
        """What :meth:`_add_info` makes of one info per rig, built a key at a time across all rigs (one array per
        key, every mask all True), where every rig's info has the same keys in the same order and each key one
        plain type (and shape and dtype: numbers, arrays, dicts) in all of them, or objects that are no dict (None,
        str ...); else None (then :meth:`_add_info`, rig by rig)."""
        first = infos[0]
        keys = list(first)
        for info in infos:
            if list(info) != keys:
                return None
        n = len(infos)
        out: dict[str, Any] = {}
        every = np.ones(n, dtype=np.bool_)  #: each key's mask is a copy of it
        for key in keys:
            if key.startswith("_") or key == "final_obs":
                return None
            values = [info[key] for info in infos]
            kind = type(values[0])
            plain = kind in (int, float, bool) or issubclass(kind, (np.number, np.ndarray, dict))
            for v in values:
                if type(v) is not kind and (plain or isinstance(v, dict)):  # objects may mix (None, str ...)
                    return None
            array: Any
            if kind is dict:
                array = self._batched_info(values)
                if array is None:
                    return None
            elif kind in (int, float, bool) or issubclass(kind, np.number):
                array = np.array(values, dtype=kind)
            elif kind is np.ndarray:
                shape, dtype = values[0].shape, values[0].dtype
                for v in values:
                    if v.shape != shape or v.dtype != dtype:
                        return None
                array = np.array(values)
            elif issubclass(kind, dict):
                return None
            else:  # as _add_info: objects, one by one
                array = np.full(n, fill_value=None, dtype=object)
                for i, v in enumerate(values):
                    array[i] = v
            out[key] = array
            out["_" + key] = every.copy()
        return out

    def _add_info(self, vector_infos: dict[str, Any], env_info: dict[str, Any], env_num: int) -> dict[str, Any]:
        """``VectorEnv._add_info`` (the same arrays, masks and key order), without allocating a
        mask it then throws away for every key of every rig."""
        n = self.num_envs
        for key, value in env_info.items():
            if key == "final_obs":
                array = vector_infos.get("final_obs")
                if array is None:
                    array = np.full(n, fill_value=None, dtype=object)
                array[env_num] = value
            elif isinstance(value, dict):
                array = self._add_info(vector_infos.get(key, {}), value, env_num)
            else:
                array = vector_infos.get(key) if key in vector_infos else None
                if array is None:
                    kind = type(value)
                    if kind in (int, float, bool) or issubclass(kind, np.number):
                        array = np.zeros(n, dtype=kind)
                    elif isinstance(value, np.ndarray):
                        array = np.zeros((n, *value.shape), dtype=value.dtype)
                    else:
                        array = np.full(n, fill_value=None, dtype=object)
                array[env_num] = value
            mask_key = "_" + key
            mask = vector_infos.get(mask_key)
            if mask is None:
                mask = np.zeros(n, dtype=np.bool_)
            mask[env_num] = True
            vector_infos[key], vector_infos[mask_key] = array, mask
        return vector_infos

    def render(self) -> tuple[Any, ...]:
        return tuple(e.render() for e in self.envs)

    def call(self, name: str, *args: Any, **kwargs: Any) -> tuple[Any, ...]:
        """Call a method (or get an attribute) of every rig's env."""
        out = []
        for e in self.envs:
            attr = getattr(e, name)
            out.append(attr(*args, **kwargs) if callable(attr) else attr)
        return tuple(out)

    def get_attr(self, name: str) -> tuple[Any, ...]:
        return tuple(getattr(e, name) for e in self.envs)

    def set_attr(self, name: str, values: Any) -> None:
        if not isinstance(values, (list, tuple)):
            values = [values] * self.num_envs
        for e, v in zip(self.envs, values):
            setattr(e, name, v)

    def close_extras(self, **kwargs: Any) -> None:
        errors = []
        for e in self.envs:
            try:
                e.close()
            except Exception as exc:  # noqa: BLE001 - close the others, then report
                errors.append(exc)
        if errors:
            raise errors[0]


class vector_entry_point:
    """The ``vector_entry_point`` of a registered id whose single env is ``env`` (``"module:Class"``);
    picklable (a spec may travel to a worker process)."""

    def __init__(self, env: str) -> None:
        self.env = env

    def __call__(self, num_envs: int = 1, **kwargs: Any) -> JointsVectorEnv:
        return JointsVectorEnv(self.env, num_envs, **kwargs)

    def __repr__(self) -> str:
        return f"vector_entry_point({self.env!r})"


def make_vector_env(env_id: str, num_envs: int, **kwargs: Any) -> JointsVectorEnv:
    """``gym.make_vec(env_id, num_envs, vectorization_mode="vector_entry_point", **kwargs)``: N rigs of
    a ``joints/`` env batched in this process."""
    vec = gym.make_vec(env_id, num_envs=num_envs, vectorization_mode="vector_entry_point", **kwargs)
    out: JointsVectorEnv = vec.unwrapped  # type: ignore[assignment]
    return out
