"""Where the time goes: ``test_sim_vs_served_timing``'s run, decomposed per transaction and per step.

Not a test (pytest does not collect it): a measuring tool. ``python tests/envs/served_timing_probe.py``
runs joints/ErobReach-v0 (position actions, seed 0, 100 steps, 25 Hz) in sim and on the hardware
backend against a served twin (``joints.sim.serve.serve`` in a child process, instrumented from the
outside: nothing in the package knows about this probe) and prints, on one clock
(``time.monotonic``, shared by the two processes):

* per transaction kind: how late the serve loop read the request after the host wrote it (OS
  scheduling of the served process), how long it held it (must be wire + t3.5 + turnaround), where
  on the world's clock it acted relative to its instant (the rule of the in-process line: the
  substep ending at or after it, 0-1 ms), how far the world lagged the wall clock then, how late the
  reply left after its instant, and how long the host's own transport took from the reply's bytes to
  returning them (beyond the t3.5 the sim counts);
* per step: when the command that starts the motion took effect and when the state was sampled,
  served minus sim (world time against the step's tick), and the host's own time per step (its
  Python between transactions and its tick's lateness);
* the per-step bus time (median and 10th percentile, both sides) and the joint positions' RMS.
"""

from __future__ import annotations

import bisect
import multiprocessing as mp
import os
import pathlib
import pickle
import statistics
import sys
import tempfile
import threading
import time
from typing import Any

import numpy as np

STEPS, PERIOD, LATENCY = 100, 0.04, 0.001
T35 = 0.00175  #: s, the silence the in-process host waits after a reply at 115200 baud
_ACTS: list[tuple[float, float, str]] = []  #: (wall, world time, request) whenever a front handles a request
_WORLD: list[Any] = [None]


def _config(port: str | None = None) -> dict[str, Any]:
    import envs

    cfg: dict[str, Any] = envs.default_config("erob_reach")
    cfg["buses"]["rs485"]["adapter_latency"] = LATENCY
    cfg["buses"]["rs485"]["timeout"] = 0.5
    if port is not None:
        cfg["buses"]["rs485"]["port"] = port
    return cfg


def _note_acts() -> None:
    from joints.sim import modbus_front as mf

    handle = mf.ModbusFront.handle

    def noted(self: Any, request: Any) -> Any:
        w = _WORLD[0]
        _ACTS.append((time.monotonic(), float(w.time) if w is not None else float("nan"), type(request).__name__))
        return handle(self, request)

    mf.ModbusFront.handle = noted  # type: ignore[method-assign]


def _server(path: str, ports: Any, stop_event: Any, out: str) -> None:
    """The served twin (child process), with its request/reply instants noted."""
    from joints.config import load
    from joints.rig import served_timing, sim_world
    from joints.sim import serve as sv
    from joints.sim import served_timing as stm
    from joints.transports import pty

    _note_acts()
    cfg = load(path, backend="sim")
    world = _WORLD[0] = sim_world(cfg)
    t0: dict[str, float] = {}
    reqs: list[tuple[float, float]] = []
    reps: list[tuple[float, float]] = []
    writes: list[float] = []
    run, request, reply, write = sv._run, stm.ServedLine.request, stm.ServedLine.reply, pty.PtyEndpoint.write

    def run_noted(w: Any, *a: Any, **k: Any) -> None:
        t0["wall"], t0["sim"] = time.monotonic(), float(w.time)
        run(w, *a, **k)

    def request_noted(self: Any, now: float, wire: float, address: int | None = None) -> float:
        due = request(self, now, wire, address)
        reqs.append((now, due))
        return due

    def reply_noted(self: Any, at: float, wire: float) -> float:
        due = reply(self, at, wire)
        reps.append((at, due))
        return due

    def write_noted(self: Any, data: bytes) -> None:
        writes.append(time.monotonic())
        write(self, data)

    sv._run = run_noted  # type: ignore[assignment]
    stm.ServedLine.request = request_noted  # type: ignore[method-assign]
    stm.ServedLine.reply = reply_noted  # type: ignore[method-assign]
    pty.PtyEndpoint.write = write_noted  # type: ignore[method-assign]
    stop = threading.Event()

    def forward() -> None:
        stop_event.wait()
        stop.set()

    threading.Thread(target=forward, daemon=True).start()
    sv.serve(world, ["rs485"], stop=stop, on_ready=lambda lines: ports.put(lines["rs485"]["port"]),
             install_signals=False, timing=served_timing(cfg))
    with open(out, "wb") as f:
        pickle.dump({"t0": t0, "acts": _ACTS, "req": reqs, "rep": reps, "wr": writes}, f)


def _episode(env: Any) -> dict[str, Any]:
    rng = np.random.default_rng(0)
    actions = rng.uniform(-1.0, 1.0, (STEPS, 1)).astype(np.float32)
    env.reset(seed=0, options={"start": [0.0], "target": [1.0]})
    records: list[Any] = []
    env.rig.trace(records.append)
    ticks, positions = [], []
    for a in actions:
        first = len(records)
        positions.append(float(env.step(a)[0][0]))
        ticks.append((env.tick_time(), first, len(records)))
    env.rig.trace(None)
    return {"records": [(r.time, r.direction, r.meaning.split("(")[0]) for r in records], "ticks": ticks,
            "positions": positions}


def _q(values: Any) -> str:
    v = np.asarray(values) * 1e3
    return f"med {np.median(v):7.3f}  p10 {np.percentile(v, 10):7.3f}  p90 {np.percentile(v, 90):7.3f} ms"


def _bus(run: dict[str, Any]) -> np.ndarray:
    out = []
    for _, a, b in run["ticks"]:
        busy, sent = 0.0, None
        for t, d, _ in run["records"][a:b]:
            if d == "tx":
                sent = t
            elif sent is not None:
                busy, sent = busy + t - sent, None
        out.append(busy)
    return np.array(out)


def _effects(run: dict[str, Any], acts: list[tuple[float, float, str]], to_rig: Any) -> np.ndarray:
    """Per step: (motion start's effect after the previous tick, state sample after the tick) on the world's clock."""
    times = [to_rig(a[1]) for a in acts]
    out = []
    for tick, _, _ in run["ticks"]:
        j = bisect.bisect_right(times, tick - PERIOD + 1e-9)
        start = next((times[i] for i in range(j, len(times)) if acts[i][2] == "WriteSingleRegister"), np.nan)
        k = bisect.bisect_right(times, tick - 1e-9)
        sample = next((times[i] for i in range(k, len(times)) if acts[i][2] == "ReadHoldingRegisters"), np.nan)
        out.append((start - (tick - PERIOD), sample - tick))
    return np.array(out)


def main() -> None:
    from envs.reach import ErobReachEnv
    from joints.cli.tomlout import dumps

    _note_acts()
    sim = ErobReachEnv(config=_config(), control_period=PERIOD)
    _WORLD[0] = sim.rig.world
    s = _episode(sim)
    s_acts = list(_ACTS)
    sim.close()
    tmp = pathlib.Path(tempfile.mkdtemp())
    (tmp / "reach.toml").write_text(dumps(_config()))
    ctx = mp.get_context("spawn")
    ports, stop = ctx.Queue(), ctx.Event()
    child = ctx.Process(target=_server, args=(str(tmp / "reach.toml"), ports, stop, str(tmp / "served.pkl")))
    child.start()
    hw = ErobReachEnv(config=_config(ports.get(timeout=120)), backend="hardware", control_period=PERIOD)
    try:
        h = _episode(hw)
    finally:
        hw.close()
        stop.set()
        child.join(30)
    srv = pickle.loads((tmp / "served.pkl").read_bytes())
    load = os.getloadavg()

    tx = [t for t, d, _ in h["records"] if d == "tx"]
    rx = [t for t, d, _ in h["records"] if d == "rx"]
    kinds = [k for _, d, k in h["records"] if d == "tx"]
    j = bisect.bisect_left([r[0] for r in srv["req"]], tx[0])
    req, rep = srv["req"][j:j + len(tx)], srv["rep"][j:j + len(tx)]
    wr = srv["wr"][bisect.bisect_left(srv["wr"], tx[0]):][:len(tx)]
    acts = srv["acts"][bisect.bisect_left([a[0] for a in srv["acts"]], tx[0]):][:len(tx)]
    t0w, t0s = srv["t0"]["wall"], srv["t0"]["sim"]
    print(f"load average {load[0]:.1f} {load[1]:.1f} {load[2]:.1f} on {os.cpu_count()} cores")
    for kind in sorted(set(kinds)):
        ix = [i for i, k in enumerate(kinds) if k == kind]
        print(f"{kind} ({len(ix)} transactions)")
        terms = {
            "request read after the host wrote it": [req[i][0] - tx[i] for i in ix],
            "held (wire + t3.5 + turnaround)": [req[i][1] - req[i][0] for i in ix],
            "acted, world time after its instant": [t0w + acts[i][1] - t0s - req[i][1] for i in ix],
            "world behind the wall clock then": [acts[i][0] - (t0w + acts[i][1] - t0s) for i in ix],
            "reply left after its instant": [wr[i] - rep[i][1] for i in ix],
            "host: reply bytes to returned, beyond t3.5": [rx[i] - wr[i] - T35 for i in ix],
            "transaction (host)": [rx[i] - tx[i] for i in ix],
        }
        for name, v in terms.items():
            print(f"  {name:44s} {_q(v)}")
    ticks = [t for t, _, _ in h["ticks"]]
    python = [tx[3 * k] - rx[3 * k - 1] + tx[3 * k + 1] - rx[3 * k] for k in range(1, STEPS)]
    late = [tx[3 * k + 2] - ticks[k] for k in range(STEPS)]
    print("per step")
    print(f"  {'host Python between transactions':44s} {_q(python)}")
    print(f"  {'host: state request after the tick':44s} {_q(late)}")
    es = _effects(s, s_acts, lambda t: t)
    eh = _effects(h, srv["acts"], lambda t: t0w + t - t0s)
    d = eh - es
    print(f"  {'motion start took effect, served - sim':44s} {_q(d[:, 0][~np.isnan(d[:, 0])])}")
    print(f"  {'state sampled, served - sim':44s} {_q(d[:, 1][~np.isnan(d[:, 1])])}")
    bs, bh = _bus(s), _bus(h)
    print(f"bus time per step: sim {_q(bs)}; served {_q(bh)}, min {bh.min() * 1e3:.3f} ms; served / sim: "
          f"median {np.median(bh) / np.median(bs) - 1:+.1%}, p10 {np.percentile(bh, 10) / np.median(bs) - 1:+.1%}, "
          f"min {bh.min() / np.median(bs) - 1:+.1%}")
    rms = float(np.sqrt(np.mean((np.array(s["positions"]) - np.array(h["positions"])) ** 2)))
    print(f"joint positions: RMS difference {rms:.3f} rad; host Python per step median "
          f"{statistics.median(python) * 1e3:.2f} ms")


if __name__ == "__main__":
    sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[2]))
    main()
