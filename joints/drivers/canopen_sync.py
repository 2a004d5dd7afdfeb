"""The SYNC cycle of one CANopen bus: each cyclic node's RPDO, one SYNC, that cycle's TPDOs; the bus's reads and
its profile-position set-points.

A SYNC is a broadcast (CiA 301): every started node answers each one with its synchronous TPDOs. A read
(:meth:`SyncCycle.read_states`, :meth:`SyncCycle.sample`) is one SYNC for all the nodes it reads and waits for
every one of their TPDOs of it; before it sends its SYNC it waits out the TPDOs still owed for an earlier SYNC
(:meth:`SyncCycle.settle`), so a TPDO taken after the SYNC answers that SYNC and no earlier one. PP set-points
(:meth:`SyncCycle.move_together`) are each node's RPDO, then one such read whose statuswords acknowledge them all.

Rule: one per bus, held by the bus's link (:attr:`joints.link.canopen.CanopenLink.sync_cycle`,
:meth:`SyncCycle.of`), shared by the drivers of that bus; it knows nodes only through
:class:`CyclicNode` (what a CANopen driver in a cyclic mode offers), not any device family.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Mapping, Sequence
from typing import Any, Protocol

from joints.codecs import canopen as co
from joints.drivers.base import RawState
from joints.errors import DeviceFault, ReplyTimeout

__all__ = ["NODE_LOST", "CyclicNode", "SetpointNode", "SyncCycle"]

from joints.devices.faults import HOST_DEFINED

#: host-defined fault: the node stopped answering (heartbeat or node guarding)
NODE_LOST = HOST_DEFINED | 0x8130


class CyclicNode(Protocol):
    """A CANopen node driven by the SYNC cycle."""

    name: str
    node: int
    tpdo1_cob: int
    status_cycle: int

    @property
    def cyclic(self) -> bool: ...

    @property
    def answers_sync(self) -> bool:
        """OPERATIONAL with its cyclic TPDO1 synchronous: it answers every SYNC on the bus."""
        ...

    def cycle_send(self, target: int) -> None: ...

    def on_tpdo(self, msg: co.Pdo) -> None: ...

    def lost(self) -> str | None: ...

    def cycle_state(self) -> RawState: ...

    def fault_text(self, code: int) -> str: ...

    @property
    def sync_cobs(self) -> tuple[int, ...]:
        """The COB-IDs of the TPDOs the node sends on every SYNC (none while not started or lost)."""
        ...

    def begin_read(self) -> bool:
        """Before a read's SYNC: the node brought up, guarded; whether it is to be sampled (not lost)."""
        ...

    def end_read(self, at: float | None) -> RawState:
        """The node's state from the TPDOs of the SYNC sent at ``at`` (clock time; None: not sampled)."""
        ...


class SetpointNode(CyclicNode, Protocol):
    """A CANopen node whose profile-position set-points the bus's :class:`SyncCycle` acknowledges by SYNC."""

    def check_move(self, target: int, speed: int | None, acc: int | None, dec: int | None) -> None:
        """The move's values against the node's ranges; raises, nothing sent."""
        ...

    def start_setpoint(self, target: int, speed: int | None, acc: int | None, dec: int | None, *,
                       relative: bool) -> None:
        """The node in PP, its profile, its RPDO with the new set-point (controlword bit 4)."""
        ...

    def setpoint_acknowledged(self, since: float) -> bool:
        """Whether its last statusword acknowledges the set-point; raises on a fault or once too long ``since``."""
        ...

    def end_setpoint(self) -> None:
        """Its RPDO with controlword bit 4 cleared."""
        ...

    def pause(self) -> None:
        """Wait a moment, keeping the bus's nodes guarded."""
        ...


class SyncCycle:
    """The SYNC cycle of one CANopen bus: each cyclic joint's RPDO, one SYNC, that cycle's TPDO1s.

    :meth:`send` waits until the cycle is due (on the rig's clock: lockstep in sim), sends the
    set-points and the SYNC; :meth:`collect` returns as soon as every joint's TPDO1 of the cycle
    is in, or at the end of the period: a TPDO that has not come by then is late (:attr:`late`
    counts them) and the joint's last values stand.

    A node answers the SYNCs in order, one TPDO1 each, so a TPDO1 answers the oldest SYNC of that
    node still unanswered (:meth:`answered`): behind a slow adapter the answer to the previous
    SYNC may reach the host after this cycle's SYNC, and it is late, not this cycle's.
    """

    def __init__(self, link: Any, period: float, *, current: bool | None = None) -> None:
        self.link = link
        self.period = period
        #: the motor current in the cyclic TPDO1: None = where the bus has room, True/False = always/never
        self.current = current
        self.cycles = 0
        self.late = 0  #: TPDOs that missed their cycle
        self.next_due: float | None = None
        self._grid = 0.0
        self._n = 0
        self.sync_time = 0.0
        self.drivers: list[CyclicNode] = []
        self._expect: list[CyclicNode] = []
        self._asked: dict[int, deque[tuple[int, float]]] = {}  #: node -> (cycle, SYNC time) not yet answered
        self._restarts = getattr(link, "restarts", 0)  #: the link's clock restarts the grid was laid after
        self._owed: dict[int, int] = {}  #: COB-ID -> TPDOs still owed for SYNCs sent (every SYNC: each sync_cobs)
        self._owed_at = 0.0  #: clock time of the last SYNC sent
        self.samples = 0  #: SYNCs sent by reads (:meth:`sample`)
        self.settled = 0  #: TPDOs of earlier SYNCs waited out before a read's SYNC
        self.acknowledges = 0  #: SYNCs sent for PP set-points' acknowledge (:meth:`setpoints`: one for all its nodes)

    @classmethod
    def of(cls, link: Any, period: float) -> SyncCycle:
        """The SYNC cycle of ``link``'s bus: the one the link holds, else a new one it then holds."""
        cycle = link.sync_cycle
        if cycle is None:
            cycle = link.sync_cycle = cls(link, period)
        assert isinstance(cycle, SyncCycle)
        return cycle

    def fits(self, rpdo_bytes: int, tpdo_bytes: int) -> bool:
        """Whether every cyclic joint of the bus, each with one RPDO and one TPDO of these sizes, fits
        the SYNC period (worst-case bit stuffing: :meth:`~joints.link.canopen.CanopenLink.cycle_load`)."""
        cyclic = [d for d in self.drivers if d.cyclic]
        load = self.link.cycle_load([d.node for d in cyclic] or [1], rpdo_bytes=(rpdo_bytes,),
                                    tpdo_bytes=(tpdo_bytes,), period=self.period)
        return bool(load.fits)

    def send(self, targets: Mapping[CyclicNode, int]) -> None:
        link = self.link
        now = link.bus_now()
        eps = 1e-9
        restarts = getattr(link, "restarts", 0)
        if restarts != self._restarts:  # the clock restarted (a sim reset): the old grid's times are void
            self._restarts = restarts
            self.next_due = None
            self._asked.clear()
            self._owed.clear()
        if self.next_due is None or now > self.next_due + self.period + eps:
            self._grid, self._n = now, 0  # first cycle, or the caller fell behind: restart the grid
        elif now < self.next_due - eps:
            link.wait_bus(self.next_due)  # TPDOs of earlier cycles still arriving are delivered as such
        self._n += 1
        due = self._grid + self._n * self.period  # on a grid: no drift
        for driver, target in targets.items():  # each send first delivers what arrived before it
            driver.cycle_send(target)
        link.sync()
        self.owe(link.clock.now())
        self.sync_time = link.bus_now()
        self.cycles += 1
        self.next_due = due
        self._expect = list(targets)
        self.synced(self.sync_time)

    # -- reads: one SYNC for the nodes read, every TPDO taken answering it -------------------------
    def owe(self, at: float) -> None:
        """A SYNC went out at clock time ``at``: every started node of the bus owes its synchronous TPDOs of it."""
        owed = self._owed
        for d in self.drivers:
            for cob in d.sync_cobs:
                owed[cob] = owed.get(cob, 0) + 1
        self._owed_at = at

    def paid(self, cob: int) -> None:
        """A TPDO with COB-ID ``cob`` came (its node's driver calls this for each one)."""
        owed = self._owed
        n = owed.get(cob)
        if n is not None:
            if n > 1:
                owed[cob] = n - 1
            else:
                del owed[cob]

    def settle(self) -> None:
        """Wait out the TPDOs still owed for earlier SYNCs, delivered to their nodes' drivers as they come (not
        taken by a read), at most until the link's reply timeout after the last SYNC; one that has not come by
        then is given up (the node is late or gone)."""
        owed = self._owed
        if not owed:
            return
        owners = {cob for d in self.drivers for cob in d.sync_cobs}
        for cob in [c for c in owed if c not in owners]:  # the node stopped or was lost meanwhile
            del owed[cob]
        if owed:
            link = self.link
            n = sum(owed.values())
            link.deliver_until(lambda: not owed, self._owed_at + link.policy.timeout - link.clock.now())
            self.settled += n - sum(owed.values())
        owed.clear()

    def sample(self, nodes: Sequence[CyclicNode]) -> float:
        """One SYNC and every TPDO of ``nodes`` answering it (each to its driver); returns the clock time the SYNC
        was sent: the nodes sample when it has crossed the bus. TPDOs owed for an earlier SYNC are waited out
        first (:meth:`settle`): a node answers the SYNCs in order, so what comes after this SYNC answers it."""
        link = self.link
        self.settle()
        link.sync()  # what arrived before it is delivered first (the send drains the bus)
        at = float(link.clock.now())
        self.samples += 1
        self.synced(link.bus_now())  # every node in a cyclic mode answers it: the SYNC cycle keeps count
        self.owe(at)
        waiting = {cob: d for d in nodes for cob in d.sync_cobs}
        deadline = at + link.policy.timeout
        while waiting:
            left = deadline - link.clock.now()
            try:
                msg = link.wait_for(lambda m: isinstance(m, co.Pdo) and m.cob_id in waiting, max(left, 0.0))
            except ReplyTimeout:
                late = sorted({d.node for d in waiting.values()})
                raise ReplyTimeout(f"{waiting[min(waiting)].name}: no TPDO from node(s) {late} after SYNC within "
                                   f"{link.policy.timeout * 1e3:.0f} ms; check that the node is OPERATIONAL") from None
            waiting.pop(msg.cob_id).on_tpdo(msg)
        return at

    def read_states(self, members: Sequence[CyclicNode]) -> dict[CyclicNode, RawState]:
        """The states of ``members`` (nodes of this bus) from one SYNC: one sample instant for all of them."""
        live = [d for d in members if d.begin_read()]
        at = self.sample(live) if live else None
        return {d: d.end_read(at if d in live else None) for d in members}

    # -- PP set-points: each node's RPDO, then one SYNC acknowledging them all -----------------------
    def move_together(self, moves: Mapping[SetpointNode, tuple[int, int | None, int | None, int | None]]) -> None:
        """Each node's PP move (target, profile speed, acceleration, deceleration in its units), every one checked
        before anything is sent (:meth:`SetpointNode.check_move`), then :meth:`setpoints`."""
        for d, (target, speed, acc, dec) in moves.items():
            d.check_move(target, speed, acc, dec)
        self.setpoints(moves, relative=False)

    def setpoints(self, moves: Mapping[SetpointNode, tuple[int, int | None, int | None, int | None]], *,
                  relative: bool) -> None:
        """CiA 402's set-point handshake for the nodes of ``moves`` together: each node's RPDO with the new
        set-point (controlword bit 4), then one SYNC that every node answers with its statusword (a SYNC is a
        broadcast), repeated for the nodes whose bit 12 does not acknowledge it yet, then each node's RPDO
        clearing bit 4. A node that shows a fault or does not acknowledge in time raises
        :class:`~joints.errors.StateError` after every started node's bit 4 is cleared."""
        started: list[SetpointNode] = []
        try:
            for d, (target, speed, acc, dec) in moves.items():
                d.start_setpoint(target, speed, acc, dec, relative=relative)
                started.append(d)
            since = float(self.link.clock.now())
            pending = started
            while pending:
                self.acknowledges += 1
                try:
                    self.sample(pending)
                except ReplyTimeout:  # the host cannot reach the bus: nothing more is sent
                    started = []
                    raise
                pending = [d for d in pending if not d.setpoint_acknowledged(since)]
                if pending:
                    pending[0].pause()
        finally:
            for d in started:
                d.end_setpoint()

    def synced(self, at: float) -> None:
        """A SYNC went out at ``at`` (the cycle's, or one a driver sent for a state read): each node that
        answers SYNCs owes a TPDO1 for it, which counts for the present cycle."""
        for d in self.drivers:
            if d.answers_sync:
                self._asked.setdefault(d.node, deque()).append((self.cycles, at))

    def answered(self, node: CyclicNode) -> int:
        """The cycle a TPDO1 of ``node`` that has just come answers: its oldest SYNC not yet answered (a
        SYNC unanswered for longer than the link's reply timeout counts as missed), else the present cycle
        (an answer to a SYNC sent outside the cycle)."""
        asked = self._asked.get(node.node)
        if not asked:
            return self.cycles
        oldest = self.link.bus_now() - self.link.policy.timeout
        while len(asked) > 1 and asked[0][1] < oldest:
            asked.popleft()
        return asked.popleft()[0]

    def collect(self) -> dict[CyclicNode, RawState]:
        link = self.link
        cycle = self.cycles
        waiting = {d.tpdo1_cob: d for d in self._expect if d.status_cycle < cycle}
        deadline = self.next_due if self.next_due is not None else link.bus_now()
        while waiting:
            left = deadline - link.bus_now()
            if left <= 1e-9:
                break
            try:
                msg = link.wait_for(lambda m: isinstance(m, co.Pdo) and m.cob_id in waiting, left)
            except ReplyTimeout:
                break
            d = waiting[msg.cob_id]
            d.on_tpdo(msg)  # its values stand either way: the freshest the host has
            if d.status_cycle >= cycle:  # else it answered an earlier SYNC: this cycle's is still to come
                del waiting[msg.cob_id]
        self.late += len(waiting)
        out: dict[CyclicNode, RawState] = {}
        for d in self._expect:
            lost = d.lost()
            if lost is not None:
                raise DeviceFault(d.name, NODE_LOST, lost, hint=d.fault_text(NODE_LOST), name="node_lost")
            out[d] = d.cycle_state()
        return out
