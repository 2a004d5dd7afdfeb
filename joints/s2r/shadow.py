"""Shadow mode: a twin beside each real joint, fed the same frames at the same times; divergence and a plot.

Rule: the real rig is not changed - its transports are tapped (every frame the host sends also goes,
at the same moment, into the twins' in-process buses; the twins' answers are dropped) and every
state the host reads from a real joint is compared with the twin's state at that moment. The twins
run in lockstep on the real rig's clock: before a frame or a comparison, their world is advanced to
the rig's time since the shadow was attached.

    with joints.open("robot.toml", backend="hardware") as rig, Shadow(rig) as shadow:
        ...                                   # drive the robot as usual
        print(shadow.summary())               # per joint: position, velocity, current divergence
        shadow.plot("shadow.png")             # real vs twin (needs matplotlib: pip install joints[plot])

The twins are built from the rig's configuration (profile overlays included: after ``joints
identify`` they are the identified joints). Attach while the joints stand still and before they
are enabled: the twins start at the real joints' measured positions, at rest, at power-on.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from types import TracebackType
from typing import Any

from joints.config import RigConfig
from joints.errors import ConfigError, JointsError
from joints.link.base import DirectFraming

__all__ = ["QUANTITIES", "Sample", "Shadow"]

#: what is compared, with its unit
QUANTITIES = {"position": "rad", "velocity": "rad/s", "current": "A"}


@dataclass(frozen=True, slots=True)
class Sample:
    """One comparison: the real joint's state as read, and its twin's at the same time."""

    t: float  #: s since the shadow was attached
    real: tuple[float, float, float]  #: position, velocity, current
    twin: tuple[float, float, float]


class Shadow:
    """Twins beside the joints of ``rig`` (see the module docstring).

    ``config``: the twins' configuration (default: the rig's, every bus simulated);
    ``perturb``: joint -> :meth:`joints.sim.world.World.perturb` arguments for the twins.
    """

    def __init__(self, rig: Any, *, config: RigConfig | None = None,
                 perturb: Mapping[str, Mapping[str, float]] | None = None) -> None:
        from joints import registry
        from joints.rig import build, sim_world
        from joints.s2r.record import _Tap

        self.rig = rig
        cfg = (config or rig.config).with_backend("sim")
        cfg = replace(cfg, on_exit="none")  # the twins only shadow: closing them sends nothing
        missing = set(rig.joints) - set(cfg.joints)
        if missing:
            raise ConfigError(f"the twins' configuration has no joints {sorted(missing)}", key="joints")
        self.world = world = sim_world(cfg)
        for name, kw in (perturb or {}).items():
            world.perturb(name, **dict(kw))
        here = {name: j.state() for name, j in rig.joints.items()}
        world.set_joint_positions({name: (s.position - rig.joints[name].offset) * rig.joints[name].direction
                                   for name, s in here.items()})
        self._t0 = float(rig.clock.now()) - world.time
        self.twin = build(cfg, transports={b: world.transport(b) for b in cfg.buses}, clock=world.clock, world=world)
        self.twin.keepalive = False
        self._medium = {b: registry.protocol(c.protocol).medium for b, c in cfg.buses.items()}
        # untimed: each host frame reaches the twins at the time the host sent it (the real bus took its time)
        self._feed = {b: registry.protocol(c.protocol).sim_transport(world.buses[b]) for b, c in cfg.buses.items()}
        self.samples: dict[str, list[Sample]] = {name: [] for name in rig.joints}
        self.frames = 0  #: host frames fed to the twins
        #: twin errors per joint: comparisons the twin could not answer (never raised into the real rig)
        self.errors: dict[str, int] = {name: 0 for name in rig.joints}
        self.last_error: dict[str, str] = {}
        self._last_tx: dict[str, float] = {}  #: bus -> time of the host's last frame on it
        self._taps: list[tuple[Any, Any, Any]] = []
        for name, bus in rig.buses.items():
            if name not in self._feed:
                continue
            framing = bus.link.framing
            if isinstance(framing, DirectFraming):
                raise ConfigError(f"bus {name!r} takes the sim's direct path, which carries no frames to shadow",
                                  key="sim.direct")
            tap = _Tap(bus.transport, name, self._on_frame, rig.clock.now)
            self._taps.append((bus, framing, bus.transport))
            bus.transport = tap
            framing.transport = tap
        self._wrapped: list[tuple[Any, Any]] = []
        for name, j in rig.joints.items():
            self._wrapped.append((j, j.__dict__.get("to_si")))
            j.to_si = self._observer(name, j.to_si)
        self.closed = False

    # -- feeding ------------------------------------------------------------------------------------
    def _advance(self, t: float) -> None:
        target = t - self._t0
        world = self.world
        steps = math.ceil((target - world.time) / world.timestep - 1e-6)
        if steps > 0:
            world.advance(steps * world.timestep)

    def _on_frame(self, frame: Any) -> None:
        if frame.direction != "tx" or self.closed:
            return
        self._advance(frame.t)
        self._last_tx[frame.bus] = frame.t
        feed = self._feed[frame.bus]
        if frame.can_id is None:
            feed.write(frame.data)
            feed.read(0.0)  # the twin's answer is not the host's business
        else:
            import can

            feed.send(can.Message(arbitration_id=frame.can_id, is_extended_id=frame.extended, data=frame.data))
            while feed.recv(0.0) is not None:
                pass
        self.frames += 1

    def _observer(self, name: str, to_si: Callable[[Any], Any]) -> Callable[[Any], Any]:
        def observed(raw: Any) -> Any:
            state = to_si(raw)
            if not self.closed:
                try:
                    self._compare(name, state)
                except JointsError as exc:  # a twin that cannot answer must never break the real rig: counted
                    self.errors[name] += 1
                    self.last_error[name] = f"{type(exc).__name__}: {exc}"
            return state
        return observed

    def _compare(self, name: str, real: Any) -> None:
        # the real drive sampled its state between the host's request and its reply: compare there
        t = real.time
        asked = self._last_tx.get(self.rig.config.joints[name].bus)
        if asked is not None and 0.0 <= t - asked <= 0.5:
            t = 0.5 * (asked + t)
        self._advance(t)
        twin = self.twin.joints[name].state()
        self.samples[name].append(Sample(t - self._t0, (real.position, real.velocity, real.current),
                                         (twin.position, twin.velocity, twin.current)))

    # -- results ------------------------------------------------------------------------------------
    def divergence(self, name: str, *, since: float = 0.0) -> dict[str, dict[str, float]]:
        """Per quantity of joint ``name`` over the samples after ``since`` [s]: RMS and largest |real - twin|,
        and the spread of the signed difference real - twin (mean, std, 5th/50th/95th percentiles)."""
        rows = [s for s in self.samples[name] if s.t >= since]
        out: dict[str, dict[str, float]] = {}
        for i, q in enumerate(QUANTITIES):
            e = sorted(s.real[i] - s.twin[i] for s in rows)
            d = [abs(x) for x in e]
            n = len(e)
            mean = sum(e) / n if n else math.nan
            out[q] = {"rms": math.sqrt(sum(x * x for x in d) / n) if n else math.nan,
                      "max": max(d) if d else math.nan, "mean": mean,
                      "std": math.sqrt(sum((x - mean) ** 2 for x in e) / n) if n else math.nan,
                      **{f"p{p}": e[min(n - 1, int(p / 100 * n))] if n else math.nan for p in (5, 50, 95)}}
        return out

    def summary(self, *, since: float = 0.0) -> dict[str, dict[str, Any]]:
        """Every joint's divergence (see :meth:`divergence`), how many samples it rests on and how many
        comparisons the twin could not answer (``errors``; the last one's text in ``last_error``)."""
        return {name: {"samples": sum(1 for s in rows if s.t >= since), "errors": self.errors.get(name, 0),
                       **({"last_error": self.last_error[name]} if name in self.last_error else {}),
                       **self.divergence(name, since=since)}
                for name, rows in self.samples.items()}

    def plot(self, path: str | Path, *, joints: Sequence[str] | None = None, dpi: int = 100) -> Path:
        """Real vs twin (position, velocity, current over time) for ``joints`` (default all) as a PNG."""
        try:
            import matplotlib
        except ImportError as exc:  # pragma: no cover - depends on the install
            from joints.errors import MissingDependencyError

            raise MissingDependencyError("matplotlib", "plot") from exc
        matplotlib.use("Agg", force=False)
        from matplotlib.figure import Figure

        names = list(joints or self.samples)
        fig = Figure(figsize=(4.5 * len(names), 7.5), dpi=dpi)
        axes = fig.subplots(len(QUANTITIES), len(names), squeeze=False, sharex="col")
        for c, name in enumerate(names):
            rows = self.samples[name]
            t = [s.t for s in rows]
            for r, (q, unit) in enumerate(QUANTITIES.items()):
                ax = axes[r][c]
                ax.plot(t, [s.real[r] for s in rows], label="real", color="tab:blue", linewidth=1.2)
                ax.plot(t, [s.twin[r] for s in rows], label="twin", color="tab:orange", linewidth=1.0, linestyle="--")
                ax.set_ylabel(f"{q} [{unit}]")
                ax.grid(True, alpha=0.3)
                if r == 0:
                    d = self.divergence(name)
                    ax.set_title(f"{name}: max |dq| {d['position']['max']:.3g} rad")
                    ax.legend(loc="best", fontsize="small")
            axes[-1][c].set_xlabel("t [s]")
        fig.tight_layout()
        p = Path(path)
        fig.savefig(p, format="png")
        return p

    # -- lifetime -----------------------------------------------------------------------------------
    def close(self) -> None:
        """Detach from the rig (its transports and joints are as before) and drop the twins."""
        if self.closed:
            return
        self.closed = True
        for bus, framing, inner in self._taps:
            bus.transport = inner
            framing.transport = inner
        for j, own in self._wrapped:
            if own is None:
                j.__dict__.pop("to_si", None)
            else:
                j.to_si = own
        try:
            self.twin.close()
        finally:
            for t in self._feed.values():
                t.close()

    def __enter__(self) -> Shadow:  # noqa: PYI034 - typing.Self needs Python 3.11
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()
