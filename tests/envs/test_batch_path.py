"""The batched path of a batch of JointsEnv rigs (``envs.batch``) gives every rig the bits of its own single env:
stepped against gymnasium's SyncVectorEnv of ``gym.make(id)`` envs, step by step, with the path asserted taken
(its counter), declined before anything is sent where a rig's own step must run, and rig by rig where an
episode ends."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

gym = pytest.importorskip("gymnasium")
pytest.importorskip("mujoco")

from gymnasium.vector import AutoresetMode

import envs  # registers the joints/ envs
from envs.vector import BATCH_MIN
from joints.sim import kernel

N = BATCH_MIN
KERNELS = ["compiled", "python"] if kernel.AVAILABLE else ["python"]

CASES = [
    ("joints/ErobReach-v0", {}),
    ("joints/ErobReach-v0", {"action_mode": "velocity"}),
    ("joints/ErobReach-v0", {"action_mode": "torque", "domain_randomization": True}),
    ("joints/ErobArmReach-v0", {"domain_randomization": True}),
    ("joints/ErobArmReach-v0", {"action_mode": "velocity"}),
]


@pytest.fixture(params=KERNELS)
def kernels(request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch) -> str:
    monkeypatch.setenv(kernel.SWITCH, "1" if request.param == "compiled" else "0")
    monkeypatch.delenv(kernel.OLD_SWITCH, raising=False)
    return str(request.param)


def _same(a: Any, b: Any, where: str) -> None:
    """Equal to the bit: types, dtypes, shapes, dict key order, values (NaN-free here)."""
    if isinstance(a, tuple):
        assert isinstance(b, tuple) and len(a) == len(b), (where, a, b)
        for i, (x, y) in enumerate(zip(a, b)):
            _same(x, y, f"{where}[{i}]")
    elif isinstance(a, dict):
        assert isinstance(b, dict) and list(a) == list(b), (where, list(a), list(b))
        for k in a:
            _same(a[k], b[k], f"{where}.{k}")
    elif isinstance(a, np.ndarray):
        assert isinstance(b, np.ndarray) and a.dtype == b.dtype and a.shape == b.shape, (where, a, b)
        if a.dtype == object:
            for x, y in zip(a, b):
                _same(x, y, where)
        else:
            assert a.tobytes() == b.tobytes(), (where, a, b)
    else:
        assert type(a) is type(b) and a == b, (where, a, b)


def _pair(env_id: str, kwargs: dict[str, Any], mode: AutoresetMode, n: int = N) -> tuple[Any, Any]:
    vec = gym.make_vec(env_id, num_envs=n, vectorization_mode="vector_entry_point", autoreset_mode=mode, **kwargs)
    ref = gym.make_vec(env_id, num_envs=n, vectorization_mode="sync", vector_kwargs={"autoreset_mode": mode},
                       **kwargs)
    return vec, ref


def _run(vec: Any, ref: Any, actions: np.ndarray, mode: AutoresetMode) -> None:
    _same(vec.reset(seed=11), ref.reset(seed=11), "reset")
    for t, a in enumerate(actions):
        if mode is AutoresetMode.DISABLED and vec.unwrapped._autoreset.any():
            mask = vec.unwrapped._autoreset.copy()
            _same(vec.reset(options={"reset_mask": mask}), ref.reset(options={"reset_mask": mask}), f"reset {t}")
        _same(vec.step(a), ref.step(a), f"step {t}")


@pytest.mark.parametrize("mode", [AutoresetMode.NEXT_STEP, AutoresetMode.DISABLED])
@pytest.mark.parametrize(("env_id", "kwargs"), CASES)
def test_batched_path_gives_each_rig_its_single_env_bits(env_id: str, kwargs: dict[str, Any], mode: AutoresetMode,
                                                        kernels: str) -> None:
    vec, ref = _pair(env_id, dict(kwargs, max_episode_steps=20), mode)
    try:
        u = vec.unwrapped
        assert u.batched and u._batch is not None
        rng = np.random.default_rng(5)
        steps = 45  # two truncations: resets between (NEXT_STEP: a step rig by rig), masked resets (DISABLED)
        _run(vec, ref, rng.uniform(-1.3, 1.3, (steps, *vec.action_space.shape)).astype(np.float32), mode)
        # every step but the NEXT_STEP resets' (two) and any that ended an episode went the batched way
        assert u.batched_steps >= steps - 4, u.batched_steps
        assert {e.compiled_path is not None for e in u.envs} == {True}
    finally:
        vec.close()
        ref.close()


def test_batched_path_off_is_the_rig_by_rig_reference() -> None:
    vec, ref = _pair("joints/ErobReach-v0", {}, AutoresetMode.NEXT_STEP)
    try:
        vec.unwrapped.batched = False
        _run(vec, ref, np.random.default_rng(1).uniform(-1, 1, (10, N, 1)).astype(np.float32), AutoresetMode.NEXT_STEP)
        assert vec.unwrapped.batched_steps == 0
    finally:
        vec.close()
        ref.close()


def test_one_rig_on_the_batched_path() -> None:
    """One rig: batched by default where the one compiled call carries it (each steady step whole in that call),
    forced onto the batched path otherwise; the sync vector env's bits either way."""
    vec, ref = _pair("joints/ErobReach-v0", {"max_episode_steps": 8}, AutoresetMode.NEXT_STEP, n=1)
    try:
        u = vec.unwrapped  # below BATCH_MIN: batched by default only where the one compiled call carries the rig
        assert u.batched == (u._batch.rigs is not None) == kernel.default_mode()
        u.batched = True
        _run(vec, ref, np.random.default_rng(2).uniform(-1, 1, (12, 1, 1)).astype(np.float32), AutoresetMode.NEXT_STEP)
        assert u.batched_steps >= 10
        if u._batch.rigs is not None:
            assert u._batch.rigs.steps_taken >= u.batched_steps - 2
    finally:
        vec.close()
        ref.close()


def test_an_ending_episode_is_finished_rig_by_rig() -> None:
    """Full torque drives the stand's joint past its position limit: that step's outcomes come from each rig's own
    ``_finish`` (terminated, the rig stopped) and the batch matches the single envs throughout."""
    vec, ref = _pair("joints/ErobReach-v0", {"action_mode": "torque", "max_episode_steps": 400},
                     AutoresetMode.NEXT_STEP)
    try:
        u = vec.unwrapped
        actions = np.ones((120, N, 1), dtype=np.float32)
        actions[:, 1] = -1.0
        _same(vec.reset(seed=3), ref.reset(seed=3), "reset")
        ended = 0
        for t, a in enumerate(actions):
            before = u.batched_steps
            out = vec.step(a)
            _same(out, ref.step(a), f"step {t}")
            if out[2].any():
                ended += 1
                assert u.batched_steps == before  # finished rig by rig
                assert out[4]["limit_violation"][out[2]].all()
        assert ended >= 1
        assert u.batched_steps > 0
    finally:
        vec.close()
        ref.close()


def test_a_bad_action_is_declined_before_anything_is_sent() -> None:
    """A non-finite action in one rig's row: the batched path sends nothing and the rigs' own steps raise their
    error, as the single envs do (the rigs before it commanded, as there)."""
    vec, ref = _pair("joints/ErobReach-v0", {}, AutoresetMode.NEXT_STEP)
    try:
        u = vec.unwrapped
        _same(vec.reset(seed=0), ref.reset(seed=0), "reset")
        a = np.zeros((N, 1), dtype=np.float32)
        _same(vec.step(a), ref.step(a), "step")
        taken = [e.compiled_path.taken for e in u.envs]
        bad = a.copy()
        bad[2, 0] = np.nan
        with pytest.raises(ValueError, match="action must be finite") as got:
            vec.step(bad)
        with pytest.raises(ValueError, match="action must be finite") as want:
            ref.step(bad)
        assert str(got.value) == str(want.value)
        assert [e.compiled_path.taken for e in u.envs] == [t + (i < 2) for i, t in enumerate(taken)]
        assert u.batched_steps == 1
    finally:
        vec.close()
        ref.close()


@pytest.mark.parametrize("env_id", ["joints/ErobReach-v0", "joints/ErobArmReach-v0"])
def test_velocity_actions_braked_at_the_limits(env_id: str) -> None:
    """Full speed towards either limit: the braking cap (both bounds) and the arm's shield bind, rig by rig as in the
    single envs."""
    vec, ref = _pair(env_id, {"action_mode": "velocity", "max_episode_steps": 400}, AutoresetMode.NEXT_STEP)
    try:
        u = vec.unwrapped
        steps = 70 if env_id == "joints/ErobReach-v0" else 40
        actions = np.ones((steps, *vec.action_space.shape), dtype=np.float32)
        actions[:, ::2] = -1.0
        _run(vec, ref, actions, AutoresetMode.NEXT_STEP)
        assert u.batched_steps == steps
        sent = np.array([e._sent for e in u.envs])
        speeds = np.abs(sent)
        assert (speeds < u.envs[0].speed_cap).any()  # some command was capped below the limit
    finally:
        vec.close()
        ref.close()


class _OwnObservation(envs.ErobReachEnv):
    """A task that replaces a method the batch writes across the rigs."""

    def _observation(self, states: Any, positions: Any = None) -> np.ndarray:
        return super()._observation(states, positions) * 1.0


def test_a_type_that_replaces_a_step_method_is_stepped_rig_by_rig() -> None:
    from envs.vector import JointsVectorEnv

    vec = JointsVectorEnv(_OwnObservation, N)
    try:
        assert vec._batch is None
        vec.reset(seed=0)
        vec.step(np.zeros((N, 1), dtype=np.float32))
        assert vec.batched_steps == 0
    finally:
        vec.close()


def test_a_rig_given_another_compiled_path_is_not_carried_by_the_one_call() -> None:
    """The rigs' one call is checked at a step's begin and kept to its finish: after a rig's compiled path is
    replaced, neither the batch's commands nor its state reads go by the one call (each rig its own), same bits."""
    import joints

    vec, ref = _pair("joints/ErobReach-v0", {}, AutoresetMode.NEXT_STEP)
    try:
        u = vec.unwrapped
        if not kernel.default_mode():
            pytest.skip("the rigs' one call needs the compiled world")
        rigs = u._batch.rigs
        actions = np.random.default_rng(4).uniform(-1, 1, (6, N, 1)).astype(np.float32)
        _same(vec.reset(seed=3), ref.reset(seed=3), "reset")
        for t in range(3):
            _same(vec.step(actions[t]), ref.step(actions[t]), f"step {t}")
        calls = rigs.taken
        assert calls >= 3  # the one call carried the first steps
        rig = u.envs[0]
        rig.compiled_path = joints.CompiledPath.build(rig.joints)
        for t in range(3, 6):
            _same(vec.step(actions[t]), ref.step(actions[t]), f"step {t}")
        assert rigs.taken == calls and u.batched_steps == 6  # batched, each rig by its own path
    finally:
        vec.close()
        ref.close()
