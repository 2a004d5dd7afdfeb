"""The exchanges' Python of two checkouts in one process: an env step's CPU time with the other checkout's functions
swapped in and out.

Not a test (pytest does not collect it): a measuring tool. ``python tests/envs/exchange_ab_probe.py OTHER ENV_ID
MODE`` (``MODE`` ``-`` for an env without action modes; ``OTHER`` the root of another checkout, e.g. a ``git
archive`` of the commit to compare with) loads OTHER's ``line_exchange``, ``erob_exchange``, ``lane``, ``params``,
``access`` and ``compiled_path`` under other names and, block by block, sets either checkout's methods of
``ErobExchange``, ``Carrier``, ``LinkLane``, ``Param.check``, ``ModbusAccess.write_request`` and ``_ErobModbus``
(and ``line_exchange``'s module functions) on the live classes. Each block is ``STEPS`` steps of the same seeded
uniform actions from the same reset, timed by ``time.thread_time``; the blocks alternate (``ROUNDS`` of each) and
every block's observations, rewards and ends must be bit-identical to the first block's. Prints the best and
median CPU time per env step of each. Pin it to one core (``taskset -c 1``). The two checkouts' classes must keep
the same attributes (methods are swapped on live objects): against a commit before g1-reply's ``_Shape.checked`` it
stops with an AttributeError.
"""

from __future__ import annotations

import os
import sys
import time
from typing import Any

import gymnasium as gym
import numpy as np

import envs  # noqa: F401 - registers the joints/ envs

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # tests/, for probekit
from probekit import load_as

from joints import compiled_path as CP
from joints.devices import params as P
from joints.drivers import access as A
from joints.link import lane as LN
from joints.sim import erob_exchange as E
from joints.sim import line_exchange as L

STEPS = int(os.environ.get("STEPS", "300"))
ROUNDS = int(os.environ.get("ROUNDS", "10"))


def _versions(other: str) -> dict[str, list[tuple[Any, str, Any]]]:
    """Per version ("this", "other"): (object, attribute, value) to set."""
    o_l = load_as(other, "joints/sim/line_exchange.py", "other_line_exchange")
    o_l._COMPILED = L._COMPILED  # the same compiled kernels (compiling again would take minutes)
    o_e = load_as(other, "joints/sim/erob_exchange.py", "other_erob_exchange")
    o_e.L = o_l
    o_ln = load_as(other, "joints/link/lane.py", "other_lane")
    o_p = load_as(other, "joints/devices/params.py", "other_params")
    o_a = load_as(other, "joints/drivers/access.py", "other_access")
    o_cp = load_as(other, "joints/compiled_path.py", "other_compiled_path")
    pairs: list[tuple[Any, Any, list[str] | None]] = [
        (E.ErobExchange, o_e.ErobExchange, None), (L.Carrier, o_l.Carrier, None), (LN.LinkLane, o_ln.LinkLane, None),
        (P.Param, o_p.Param, ["check"]), (A.ModbusAccess, o_a.ModbusAccess, ["write_request"]),
        (CP._ErobModbus, o_cp._ErobModbus, None)]
    out: dict[str, list[tuple[Any, str, Any]]] = {}
    for tag, pick in (("this", 0), ("other", 1)):
        sets = []
        for mine, theirs, names in pairs:
            for n in names or [n for n, v in vars(mine).items() if callable(v) and not isinstance(v, type)]:
                src = (mine, theirs)[pick].__dict__.get(n)
                if src is not None:
                    sets.append((mine, n, src))
        for n in ("stock", "clear", "fill", "fused", "book"):
            sets.append((L, n, getattr((L, o_l)[pick], n)))
        out[tag] = sets
    return out


def main(other: str, env_id: str, mode: str) -> None:
    versions = _versions(other)
    this_sets = list(versions["this"])
    kwargs: dict[str, Any] = {} if mode == "-" else {"action_mode": mode}
    env = gym.make(env_id, **kwargs)
    shape: tuple[int, ...] = env.action_space.shape or ()
    actions = np.random.default_rng(0).uniform(-1, 1, (STEPS, *shape)).astype(np.float32)

    def use(tag: str) -> None:
        for obj, n, f in versions[tag]:
            setattr(obj, n, f)

    def block() -> tuple[float, list[Any]]:
        env.reset(seed=0)
        seen = []
        t = time.thread_time()
        for a in actions:
            o, r, te, tr, _ = env.step(a)
            seen.append((o.tobytes(), r, te, tr))
            if te or tr:
                env.reset(seed=1)
        return (time.thread_time() - t) / STEPS * 1e6, seen

    for tag in ("other", "this"):  # warm
        use(tag)
        block()
    got: dict[str, list[float]] = {"this": [], "other": []}
    first = None
    for k in range(ROUNDS):
        for tag in ("other", "this") if k % 2 == 0 else ("this", "other"):
            use(tag)
            us, seen = block()
            first = seen if first is None else first
            assert seen == first, f"{tag}: the bits differ"
            got[tag].append(us)
    for obj, n, f in this_sets:
        setattr(obj, n, f)
    print(f"{env_id} {mode}: other best {min(got['other']):.1f} median {np.median(got['other']):.1f} | this best "
          f"{min(got['this']):.1f} median {np.median(got['this']):.1f} us CPU per env step ({ROUNDS} x {STEPS} each)")


if __name__ == "__main__":
    main(*sys.argv[1:4])
