"""Every bit of many env runs, recorded, to compare two checkouts (or two kernel settings) run for run.

Not a test (pytest does not collect it): a checking tool for changes that must keep the envs' bits. ``python
tests/envs/bits_probe.py record OUT.pkl`` runs 51 cases - each env in every action mode with and without domain
randomisation (two seeds), the driver path (``compiled_path=False``), the stand and the arm at 20 ms on CAN, the
diff-drive and the MKS axis, and the batched env (5 rigs) in the three autoreset modes with masked resets - and
pickles every observation, reward, termination, truncation and info (key order included), every joint's last
state, and at the end the links' transaction and frame counts, every twin's register image, the rig's time and the
world's substeps. ``python tests/envs/bits_probe.py compare A.pkl B.pkl`` names the first difference of each case
that differs. Record each checkout with ``PYTHONPATH`` set to it, with numba and with ``JOINTS_COMPILED=0``
(each compared only with its own kind).
"""

from __future__ import annotations

import pickle
import sys

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode

import envs  # noqa: F401 - registers the joints/ envs


def _enc(v):
    if isinstance(v, np.ndarray):
        return ("nd", v.dtype.str, v.shape, v.tobytes() if v.dtype != object else repr([_enc(x) for x in v.tolist()]))
    if isinstance(v, dict):
        return ("d", [(k, _enc(x)) for k, x in v.items()])  # key ORDER included
    if isinstance(v, (list, tuple)):
        return (type(v).__name__, [_enc(x) for x in v])
    return (type(v).__name__, repr(v))


def _images(u):
    out = []
    for name, bus in sorted(u.rig.sim.buses.items()):
        if not hasattr(bus, "slaves"):
            out.append((name, repr(type(bus))))
            continue
        for address, front in sorted(bus.slaves.items()):
            out.append((name, address, tuple(sorted(front.image().items()))))
    return out


def _links(u):
    seen = {}
    for j in u.rig.joints.values():
        link = j.driver.access.link
        seen.setdefault(id(link), link)
    return [
        (
            getattr(lk, "transactions", None),
            getattr(getattr(lk, "framing", None), "exchanges", None),
            getattr(lk, "retries_used", None),
            len(getattr(getattr(lk, "transport", None), "log", ()) or ()),
        )
        for lk in seen.values()
    ]


def run_single(env_id, kwargs, seed, steps, amp):
    env = gym.make(env_id, **kwargs)
    u = env.unwrapped
    out = []
    try:
        obs, info = env.reset(seed=seed)
        out.append(("reset", _enc(obs), _enc(info)))
        rng = np.random.default_rng(seed + 100)
        for k in range(steps):
            a = rng.uniform(-amp, amp, env.action_space.shape).astype(np.float32)
            if k % 17 == 5:
                a[:] = amp  # extremes
            obs, r, te, tr, info = env.step(a)
            out.append(
                (
                    _enc(obs),
                    _enc(r),
                    _enc(te),
                    _enc(tr),
                    _enc(info),
                    [(repr(j.last_state), j.enabled) for j in u.rig.joints.values()],
                )
            )
            if te or tr:
                obs, info = env.reset()
                out.append(("reset", _enc(obs), _enc(info)))
        out.append(
            (
                "end",
                _links(u),
                _images(u),
                u.rig.time,
                u.rig.sim.steps,
                u.overruns,
                u.overrun_time,
                None if getattr(u, "compiled_path", None) is None else u.compiled_path.taken,
            )
        )
    finally:
        env.close()
    return out


def run_vec(env_id, n, kwargs, seed, steps, mode):
    vec = gym.make_vec(env_id, num_envs=n, vectorization_mode="vector_entry_point", autoreset_mode=mode, **kwargs)
    u = vec.unwrapped
    out = []
    try:
        obs, info = vec.reset(seed=seed)
        out.append(("reset", _enc(obs), _enc(info)))
        rng = np.random.default_rng(seed + 200)
        for k in range(steps):
            a = rng.uniform(-1.1, 1.1, vec.action_space.shape).astype(np.float32)
            if mode == AutoresetMode.DISABLED and k and u._autoreset.any():
                obs, info = vec.reset(options={"reset_mask": u._autoreset.copy()})
                out.append(("mreset", _enc(obs), _enc(info)))
            obs, r, te, tr, info = vec.step(a)
            out.append((_enc(obs), _enc(r), _enc(te), _enc(tr), _enc(info)))
        out.append(("end", [(_links(e), _images(e), e.rig.time, e.rig.sim.steps) for e in u.envs]))
    finally:
        vec.close()
    return out


CASES = []
for mode in ("position", "velocity", "torque"):
    for dr in (False, True):
        for seed in (1, 2):
            CASES.append(("joints/ErobReach-v0", {"action_mode": mode, "domain_randomization": dr}, seed, 300, 1.3))
            CASES.append(("joints/ErobArmReach-v0", {"action_mode": mode, "domain_randomization": dr}, seed, 120, 1.3))
    CASES.append(("joints/ErobReach-v0", {"action_mode": mode, "compiled_path": False}, 3, 60, 1.0))
    CASES.append(("joints/ErobArmReach-v0", {"action_mode": mode, "compiled_path": False}, 3, 40, 1.0))
    from joints.bench import _baseline_config

    for eid in ("joints/ErobArmReach-v0", "joints/ErobReach-v0"):
        CASES.append(
            (eid, {"action_mode": mode, "control_period": 0.02, "config": _baseline_config(eid)[0]}, 4, 60, 1.0)
        )
for dr in (False, True):
    CASES.append(("joints/DiffDriveGoal-v0", {"domain_randomization": dr}, 5, 200, 1.2))
CASES.append(("joints/MksAxisPosition-v0", {}, 6, 120, 1.2))


def record(path: str, quick: bool = False) -> None:
    res = {}
    for i, (eid, kw, seed, steps, amp) in enumerate(CASES):
        key = f"{eid} {sorted(kw.items())} {seed}"
        try:
            res[key] = run_single(eid, kw, seed, steps if not quick else 10, amp)
        except Exception as exc:  # noqa: BLE001 - an error is a result too (it must be the same)
            res[key] = ("error", repr(exc))
        print(key, "ok" if res[key][0] != "error" else res[key], flush=True)
    for mode in (AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP, AutoresetMode.DISABLED):
        for eid, kw in (
            ("joints/ErobReach-v0", {"domain_randomization": True}),
            ("joints/ErobReach-v0", {"action_mode": "torque"}),
            ("joints/ErobArmReach-v0", {"action_mode": "velocity"}),
            ("joints/DiffDriveGoal-v0", {}),
        ):
            key = f"vec {eid} {mode} {sorted(kw.items())}"
            res[key] = run_vec(eid, 5, dict(kw, max_episode_steps=37), 9, 90 if not quick else 5, mode)
            print(key, "ok", flush=True)
    with open(path, "wb") as f:
        pickle.dump(res, f)


def compare(path_a: str, path_b: str) -> int:
    """Print the first difference of each case that differs; the number of such cases."""
    with open(path_a, "rb") as f:
        a = pickle.load(f)
    with open(path_b, "rb") as f:
        b = pickle.load(f)
    if a.keys() != b.keys():
        print("cases differ:", sorted(set(a) ^ set(b)))
        return len(set(a) ^ set(b))
    bad = 0
    for k in a:
        if a[k] == b[k]:
            continue
        bad += 1
        for i, (p, q) in enumerate(zip(a[k], b[k])):
            if p != q:
                print("DIFF", k, "at", i, str(p)[:200], "\n   vs", str(q)[:200])
                break
        else:
            print("DIFF", k, "length", len(a[k]), len(b[k]))
    print(f"{len(a)} cases, {bad} differ")
    return bad


if __name__ == "__main__":
    if sys.argv[1:2] == ["record"]:
        record(sys.argv[2], quick="--quick" in sys.argv)
    elif sys.argv[1:2] == ["compare"]:
        sys.exit(1 if compare(sys.argv[2], sys.argv[3]) else 0)
    else:
        sys.exit(__doc__)
