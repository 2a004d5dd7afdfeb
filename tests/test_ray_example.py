"""The Ray example tunes on a local Ray cluster of two nodes (one worker CPU each), CI-sized.

Ray is in the ``dev`` extra; the only reason to skip is a platform without a Ray wheel.
"""

from __future__ import annotations

import os
import pickle
import sys
from pathlib import Path

import pytest

ray = pytest.importorskip("ray", reason="no Ray wheel for this platform")
pytest.importorskip("mujoco")
pytest.importorskip("gymnasium")

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "examples"))
import ray_tune_reach

import envs


def test_env_config_pickles_and_builds_the_same_env_anywhere() -> None:
    cfg = pickle.loads(pickle.dumps({**ray_tune_reach.ENV_CONFIG, "max_episode_steps": 5}))
    a, b = envs.make_env(cfg), envs.make_env(cfg)
    try:
        assert (a.reset(seed=3)[0] == b.reset(seed=3)[0]).all()
        assert a.unwrapped.rig is not b.unwrapped.rig  # nothing shared
    finally:
        a.close()
        b.close()
    with pytest.raises(TypeError, match="id"):
        envs.make_env({"action_mode": "velocity"})


@pytest.mark.slow
def test_tune_on_a_two_node_local_cluster(tmp_path: Path) -> None:
    from ray.cluster_utils import Cluster

    cluster = Cluster(initialize_head=True, head_node_args={"num_cpus": 1, "include_dashboard": False})
    try:
        cluster.add_node(num_cpus=1)
        # workers import this checkout (and the example) as the driver does
        path = f"{ROOT}{os.pathsep}{ROOT / 'examples'}"
        ray.init(address=cluster.address, log_to_driver=False, runtime_env={"env_vars": {"PYTHONPATH": path}})
        try:
            assert ray.cluster_resources()["CPU"] == 2
            best, scores = ray_tune_reach.tune_gains([0.05, 4.0], episodes=1, steps=25, num_envs=2,
                                                     storage=str(tmp_path))
        finally:
            ray.shutdown()
    finally:
        cluster.shutdown()
    assert set(scores) == {0.05, 4.0}
    # the same trial in this process gives the same return: workers build the env from the config alone
    local = ray_tune_reach.evaluate(4.0, {**ray_tune_reach.ENV_CONFIG, "num_envs": 2}, episodes=1, steps=25, seed=0)
    assert scores[4.0] == pytest.approx(local)
    assert best == 4.0 and scores[4.0] > scores[0.05]  # a stiffer controller reaches the target
