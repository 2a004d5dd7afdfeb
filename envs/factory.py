"""Envs from a plain config: what a worker process (Ray, a subprocess vector env) builds its env from.

Rule: the config is plain data - ``{"id": "joints/ErobReach-v0", ...the env's arguments}``, plus
``"num_envs"`` for N rigs batched in one process - so it pickles and travels to any worker; the
worker imports :mod:`envs` (which registers the ids) and makes the env there. Nothing is shared
between envs or processes: each env opens its own rig (and, in sim, its own MuJoCo model).

>>> env = envs.make_env({"id": "joints/ErobReach-v0", "action_mode": "velocity"})        # doctest: +SKIP
>>> vec = envs.make_env({"id": "joints/ErobReach-v0", "num_envs": 8})                     # doctest: +SKIP

RLlib: ``ray.tune.registry.register_env("erob_reach", envs.make_env)`` and pass the config as the
algorithm's ``env_config``.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import gymnasium as gym

__all__ = ["make_env"]


def make_env(config: Mapping[str, Any]) -> Any:
    """The env (or, with ``num_envs``, the batched vector env) a config describes."""
    import envs  # noqa: F401 - registers the joints/ ids in this process

    cfg = dict(config)
    env_id = cfg.pop("id", None)
    if not isinstance(env_id, str):
        raise TypeError(f"an env config needs the env's id (e.g. 'joints/ErobReach-v0'), got {config!r}")
    num_envs = cfg.pop("num_envs", None)
    if num_envs is None:
        return gym.make(env_id, **cfg)
    from envs.vector import make_vector_env

    return make_vector_env(env_id, int(num_envs), **cfg)
