"""The compiled path's step of one eRob on the CAN custom protocol: its steady requests in one call of the twin.

Rule: what :class:`~joints.drivers.erob_can.ErobCanDriver` and its :class:`~joints.link.erob_can.ErobCanLink`
do for a steady command (target + "start"; a speed or current set-point: one write of the analog value 0x01FE)
and a state read - the joint's checks, the driver's steady compare and range checks,
the same request objects (``ErobCanAccess.message``; the state's reads as ``ErobCanAccess.read`` makes them),
encoded by the rule before anything is sent, counted by the link, each reply taken as the rule's ``is_reply``
takes it (an error reply raises its :class:`~joints.errors.DeviceRejected` as the link raises it; an ``Ack`` or
a read's value, which the stock rule takes by the request's type and node alone, proven once by the rule and
then taken without the reply object), the link's fence
bookkeeping, the driver's cache and temperature bookkeeping, the joint's contact - with the frames, the physics
between them and the drive's ops in one call of the twin's one-call exchange (the sim's
:mod:`joints.sim.can_exchange`, reached through the in-process medium's peer: nothing of the sim is imported
here). Where the link, the driver or the twin is not in the steady case (a trace, a node to fence, a setting to
write, anything the exchange refuses before sending) the joint's own method runs instead, so the result is
the driver path's in every case. An env's whole steady step - the command, the env's wait for its tick (the world
holding the rig's sleep) and the state read - goes in one call (:meth:`ErobCanStep.step`); where it cannot, nothing
is sent and the env does the three. Used by :mod:`joints.compiled_path`.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

from joints.codecs import erob_can as ec
from joints.devices.erob.can import CanMap
from joints.devices.params import ParamMap
from joints.drivers import erob_can as erob_can_driver
from joints.drivers.erob import CMD_START
from joints.drivers.erob_can import ErobCanAccess, ErobCanDriver
from joints.errors import UnexpectedReply
from joints.link.base import FrameFraming, Link
from joints.link.erob_can import ErobCanLink, ErobCanRule

if TYPE_CHECKING:
    from joints.joint import Joint, JointState

__all__ = ["ErobCanStep", "stepper"]

#: the host's methods a request goes through, as defined (a replaced one: the joint's own method)
_STOCK = tuple((cls, name, getattr(cls, name)) for cls, names in (
    (Link, ("request", "_attempts", "_once", "_await_reply", "_drain", "_unsolicited")),
    (ErobCanLink, ("_once", "_guarded", "_fence")),
    (ErobCanRule, ("is_reply", "encode", "check", "expects_reply")),
    (FrameFraming, ("write", "receive")),
) for name in names) + ((ec, "answers", ec.answers), (ec, "encode", ec.encode))  # (what the stock rule calls)
#: what a read's value goes through on the host (``CanMap.from_wire`` and the map's lookups it calls), as defined
_DECODE = ((CanMap, "from_wire", CanMap.from_wire), (CanMap, "param", ParamMap.param), (CanMap, "key", ParamMap.key))
_I32 = (-0x80000000, 0x7FFFFFFF)
#: the driver's state rule as defined (a replaced one: no one-call step, see :meth:`ErobCanStep.step`)
_STATE_NAMES, _STATE_READ = ErobCanDriver.state_names, ErobCanDriver.state_read


def _stock(methods: tuple[tuple[Any, str, Any], ...] = _STOCK) -> bool:
    """Whether none of ``methods`` (:data:`_STOCK`) is replaced."""
    for cls, name, fn in methods:
        if getattr(cls, name) is not fn:
            return False
    return True


class _Counts:
    """Requests sent by the one-call exchange (``fused``; all of them ``taken`` by it), as a lane counts them."""

    def __init__(self) -> None:
        self.fused = 0
        self.taken = 0


class ErobCanStep:
    """One eRob on an eRob CAN link whose peer is an in-process twin offering a one-call exchange."""

    def __init__(self, joint: Joint, driver: ErobCanDriver, exchange: Any) -> None:
        self.joint = joint
        self.driver = driver
        access = driver.access
        assert isinstance(access, ErobCanAccess)
        self.access = access
        self.link: ErobCanLink = driver.link
        self.clock = driver.clock
        self.exchange = exchange
        self.node = access.node
        self.lane = _Counts()
        self.taken = 0  #: joint steps (commands: a target + start, or a set-point) sent by the exchange
        self.start = access.message("start_operating", CMD_START)
        self.link.rule.check(self.start)
        self._reads: dict[tuple[str, ...], tuple[ec.Read, ...]] = {}
        #: names whose ``from_wire`` is the wire value itself (see :meth:`_plain`), for the map they were seen in
        self._plain_of: tuple[Any, set[tuple[str, ...]]] = (None, set())
        #: reads tuples whose value replies the stock ``is_reply`` was seen to take (see :meth:`_send_values`)
        self._answered: set[int] = set()
        #: (node, index, subindex) of writes the stock rule encoded (see :meth:`_check`); (request type, node) of
        #: requests whose ``Ack`` the stock ``is_reply`` took (see :meth:`_take`)
        self._encoded: set[tuple[int, int, int | None]] = set()
        self._acked: set[tuple[type, int]] = set()
        self.values_taken = 0  #: state reads taken by their values (:meth:`_send_values`)
        self.acks_taken = 0  #: commands whose Acks were taken without the objects (:meth:`_send_acks`)

    def _reads_of(self, names: tuple[str, ...]) -> tuple[ec.Read, ...]:
        """The reads ``ErobCanAccess.read`` sends for ``names`` (checked once: constants)."""
        reads = self._reads.get(names)
        if reads is None:
            cmap = self.access.map
            out = []
            for name in names:
                key = cmap.key(name)
                out.append(ec.Read(self.node, key.index, key.subindex))
            for r in out:
                self.link.rule.check(r)
            reads = self._reads[names] = tuple(out)
        return reads

    def _steady(self) -> bool:
        """Whether the link is in the steady case: no trace, no node to fence, the stock classes and methods."""
        link = self.link
        return link.trace is None and self.node not in link._unsynced and type(link) is ErobCanLink and \
            type(link.rule) is ErobCanRule and type(link.framing) is FrameFraming and _stock()

    def _check(self, request: Any, steady: bool) -> None:
        """``rule.check(request)``: raises :class:`~joints.errors.EncodeError` before anything is sent. With the
        stock rule (``steady``: :meth:`_steady` held just now) the frame is built once per (node, index, subindex):
        ``ec.encode`` of a write checks those and its value's int32 range only, and the range is checked here."""
        key = (request.node, request.index, request.subindex)
        value = request.value
        if steady and type(value) is int and _I32[0] <= value <= _I32[1] and key in self._encoded and \
                type(request) is ec.Write:
            return
        self.link.rule.check(request)
        if steady and type(request) is ec.Write:
            self._encoded.add(key)

    def _send_acks(self, requests: tuple[Any, ...], steady: bool) -> tuple[int, Any] | None:
        """The twin's answers to ``requests`` (writes and commands) by one call of its exchange, without the
        ``Ack`` objects (counted as the link counts them): (how many were done, the refused start's error reply -
        the last done - or None, for :meth:`_take`); None (nothing sent) where the link is not in the steady case
        (``steady``: :meth:`_steady`, asked by the caller just before).

        The proof, once per (request type, node): the exchange answers every request it does not refuse with
        ``Ack(request.node)`` (``ErobCanExchange.acks``); the stock ``ErobCanRule.is_reply`` (with the stock
        ``ec.answers``, both checked before every call) takes such an ``Ack`` by the request's type and node alone,
        so it takes each one where it took one - asked here once, by the rule itself (as :meth:`_take` asks)."""
        if not steady:
            return None
        link = self.link
        acked = self._acked
        for r in requests:
            if (type(r), r.node) not in acked:
                if not link.rule.is_reply(r, ec.Ack(r.node)):
                    return None
                acked.add((type(r), r.node))
        with link._lock:
            got: tuple[int, Any] | None = self.exchange.acks(requests, link.policy.timeout)
            if got is None:
                return None
            link.transactions += got[0]
        self.lane.fused += got[0]
        self.lane.taken += got[0]
        self.acks_taken += 1
        return got

    def _send_values(self, reads: tuple[ec.Read, ...]) -> list[int] | None:
        """The values the twin answers to ``reads`` (a tuple of :meth:`_reads_of`) by one call of its exchange, taken
        as :meth:`_take` takes their replies, without the replies; None (nothing sent) as for :meth:`_send_acks`.

        The proof, once per tuple: the exchange answers a read only by ``ValueReply(read.node, value)``; the stock
        ``ErobCanRule.is_reply`` (with the stock ``ec.answers``, both checked before every call) asks of such a
        reply its type and node only, so it takes every value where it took the value 0 - asked here once, by the
        rule itself. (``_take``'s ``_unsynced.discard`` has nothing to do: the steady case has the node synced.)"""
        if not self._steady():
            return None
        link = self.link
        if id(reads) not in self._answered:
            if not all(link.rule.is_reply(r, ec.ValueReply(r.node, 0)) for r in reads):
                return None
            self._answered.add(id(reads))  # (the tuple is kept in ``_reads``: its id is not reused)
        with link._lock:
            values: list[int] | None = self.exchange.values(reads, link.policy.timeout)
            if values is None:
                return None
            link.transactions += len(values)
        self.lane.fused += len(values)
        self.lane.taken += len(values)
        self.values_taken += 1
        return values

    def _take(self, request: Any, reply: Any) -> Any:
        """``reply`` taken as the link takes it (an error reply raises here, as it raises there). An ``Ack`` from
        the request's node is taken by the stock ``is_reply`` (checked before the call) by the request's type and
        node alone: asked once per (type, node), by the rule itself."""
        if type(reply) is ec.Ack and reply.node == request.node and (type(request), request.node) in self._acked:
            return reply
        link = self.link
        if type(reply) is ec.Ack and reply.node == request.node and link.rule.is_reply(request, reply):
            self._acked.add((type(request), request.node))
            return reply
        if not link.rule.is_reply(request, reply):  # (a steady reply always answers its request)
            raise UnexpectedReply(f"{link.name}: the twin's one-call exchange answered {request!r} with {reply!r}, "
                                  "which does not answer it (a fault of the emulator: report it)")
        if isinstance(reply, ec.ValueReply):
            link._unsynced.discard(request.node)
        return reply

    # -- what the compiled path calls -----------------------------------------------------------
    def carried(self) -> tuple[Any, list[Any]] | None:
        """(the world, the twins of the exchange's bus) for ``compiled_path._hold_sleeps``: the world's sleeps may
        be held (``World.hold``, where the bus lets them: its ``holds()``) and run by the next call."""
        exchange = self.exchange
        return exchange.world, [f.firmware for f in exchange.bus.fronts]

    def command_all(self, mode: str, values: Sequence[float], skip: Sequence[bool]) -> None:
        if not skip[0]:
            self.command(mode, values[0])

    def states(self) -> list[JointState]:
        return [self.state()]

    def command(self, mode: str, value: float) -> None:
        joint, driver = self.joint, self.driver
        if mode == "position":
            target, speed, acc, dec = joint.position_command(value)
            if driver.steady_move(speed, acc, dec):
                driver.validate(target_absolute_position=target)
                request = self.access.message("target_absolute_position", target)
                steady = self._steady()
                self._check(request, steady)  # raises EncodeError before anything is sent
                got = self._send_acks((request, self.start), steady)
                if got is not None:  # (the target write is acknowledged: the call carries only writes it takes)
                    self._moved(target, got, (request, self.start), None)
                    return
            driver.move_to(target, speed=speed, acceleration=acc, deceleration=dec)
            joint.note_contact()
        elif mode == "velocity":  # Joint.set_velocity: its checks (and contact), then ErobCanDriver.set_velocity
            speed, ramp = joint.velocity_command(value)
            if driver.steady_velocity(ramp, ramp):
                driver.validate(analog_quantity_value=speed, target_speed=speed)
                if self._setpoint(speed):
                    return
            driver.set_velocity(speed, acceleration=ramp, deceleration=ramp)
        else:  # Joint.set_torque: its checks, ErobCanDriver.set_current, then the contact
            current = joint.torque_command(value)
            if driver.steady_current():
                driver.validate(analog_quantity_value=current, target_current=current)
                if self._setpoint(current):
                    joint.note_contact()
                    return
            driver.set_current(current)
            joint.note_contact()

    def _moved(self, target: int, got: tuple[int, Any], requests: tuple[Any, ...], at: float | None) -> None:
        """A steady move's bookkeeping after the exchange carried it (``got``: :meth:`_send_acks`'s; ``at``: the
        clock after it, None: now): the target noted, a refused start raised, the contact."""
        self.driver.note_written("target_absolute_position", target)
        if got[1] is not None:
            self._take(requests[got[0] - 1], got[1])  # refused: raises DeviceRejected
        self.taken += 1
        self.joint.note_contact(at)

    def _setpoint(self, value: int) -> bool:
        """The steady set-point (``ErobCanDriver._analog`` with its settings held and the settle wait over: one
        write of the analog value 0x01FE) by one call of the twin's exchange; False: not sent (the driver's own
        method sends it)."""
        request = self.access.message("analog_quantity_value", value)
        steady = self._steady()
        self._check(request, steady)  # raises EncodeError before anything is sent
        got = self._send_acks((request,), steady)
        if got is None:
            return False
        self._set(value, got, request)
        return True

    def _set(self, value: int, got: tuple[int, Any], request: Any) -> None:
        """A steady set-point's bookkeeping after the exchange carried it (``got``: :meth:`_send_acks`'s)."""
        if got[1] is not None:
            self._take(request, got[1])  # (never: a set-point is not refused; as the link takes a refusal)
        self.driver.note_written("analog_quantity_value", value)
        self.taken += 1

    def state(self) -> JointState:
        clock, driver = self.clock, self.driver
        t0 = clock.now()
        names = driver.state_names(t0)
        values = self._send_values(self._reads_of(names))
        if values is None:
            return self.joint.state()
        return self._state_of(names, values, t0, clock.now())

    def _state_of(self, names: tuple[str, ...], values: list[int], t0: float, t1: float) -> JointState:
        """The joint's state from the values of ``names`` read between the clock instants ``t0`` and ``t1``."""
        if self._plain(names):
            v = dict(zip(names, values))
        else:
            from_wire = self.access.map.from_wire
            v = {name: from_wire(name, value) for name, value in zip(names, values)}
        return self.joint.to_si(self.driver.state_read(v, t0, t1))

    # -- an env step in one call ----------------------------------------------------------------
    def step(self, mode: str, values: Sequence[float], tick: float) -> tuple[list[JointState], float] | None:
        """:meth:`CompiledPath.step <joints.compiled_path.CompiledPath.step>` of this joint: :meth:`command`'s
        steady command, the env's wait for its tick at clock time ``tick`` (``RigEnv._wait_until``: the world
        holds the rig's sleep) and :meth:`state`'s read in one call of the twin's exchange
        (:meth:`~joints.sim.can_exchange.ErobCanExchange.step`): (the state, what was left to the tick - the tick
        less the clock after the command). The read's names are ``driver.state_names`` at the clock after the
        wait: the temperature read, where it may fall due, is the call's last and made by the call's own test of
        that clock. None (nothing sent) where any part is not the steady case or the command's checks refuse
        (the command's own way raises it again)."""
        driver = self.driver
        if self.exchange.world.clock is not self.clock or type(driver).state_names is not _STATE_NAMES or \
                type(driver).state_read is not _STATE_READ or not self._steady():
            return None
        try:
            planned = self._plan(mode, values[0])
        except Exception:  # noqa: BLE001 - a refusal: the command's own way raises it again
            return None
        if planned is None:
            return None
        requests, value = planned
        link = self.link
        if not self._proven(requests):
            return None
        cached = driver._temperature
        full = (*erob_can_driver.CAN_STATUS_NAMES, erob_can_driver.TEMPERATURE)
        reads = self._reads_of(full)
        if id(reads) not in self._answered:
            if not all(link.rule.is_reply(r, ec.ValueReply(r.node, 0)) for r in reads):
                return None
            self._answered.add(id(reads))
        with link._lock:
            got = self.exchange.step(requests, tick, reads, link.policy.timeout,
                                     None if cached is None else cached[0], erob_can_driver.TEMPERATURE_PERIOD)
            if got is None:
                return None
            read = got.read
            link.transactions += got.done + (0 if read is None else len(read[2]))
        self._carried(mode, value, requests, got)
        if read is None:  # a set-point was held: the bus ticks, the world does not hold the sleep - as the env does
            return self._wait_and_read(tick)
        remaining, t0, vals = read
        n = len(vals)
        self.lane.fused += n
        self.lane.taken += n
        self.values_taken += 1
        names = full if n == len(full) else full[:n]
        if driver.state_names(t0) != names:
            raise RuntimeError(f"{link.name}: the one-call step read {names} but the driver reads "
                               f"{driver.state_names(t0)} at {t0!r}; this is a bug")
        return [self._state_of(names, vals, t0, self.clock.now())], remaining

    def _plan(self, mode: str, value: float) -> tuple[tuple[Any, ...], int] | None:
        """:meth:`command`'s steady requests for ``value`` in ``mode`` (its checks made; they raise) and the
        value they carry, or None where the command is not the steady one (the link is steady: asked before)."""
        joint, driver = self.joint, self.driver
        if mode == "position":
            target, speed, acc, dec = joint.position_command(value)
            if not driver.steady_move(speed, acc, dec):
                return None
            driver.validate(target_absolute_position=target)
            request = self.access.message("target_absolute_position", target)
            self._check(request, True)
            return (request, self.start), target
        if mode == "velocity":
            v, ramp = joint.velocity_command(value)
            if not driver.steady_velocity(ramp, ramp):
                return None
            driver.validate(analog_quantity_value=v, target_speed=v)
        else:
            v = joint.torque_command(value)
            if not driver.steady_current():
                return None
            driver.validate(analog_quantity_value=v, target_current=v)
        request = self.access.message("analog_quantity_value", v)
        self._check(request, True)
        return (request,), v

    def _proven(self, requests: tuple[Any, ...]) -> bool:
        """:meth:`_send_acks`'s proof for ``requests``: the stock rule takes each one's ``Ack`` (once per (request
        type, node))."""
        link, acked = self.link, self._acked
        for r in requests:
            if (type(r), r.node) not in acked:
                if not link.rule.is_reply(r, ec.Ack(r.node)):
                    return False
                acked.add((type(r), r.node))
        return True

    def _carried(self, mode: str, value: int, requests: tuple[Any, ...], got: Any) -> None:
        """:meth:`command`'s bookkeeping after a step's call carried its requests (``got``: the exchange's
        ``Stepped``): counted as :meth:`_send_acks` counts them, then the move's or the set-point's."""
        done = got.done
        self.lane.fused += done
        self.lane.taken += done
        self.acks_taken += 1
        ack = (done, got.refusal)
        if mode == "position":
            self._moved(value, ack, requests, got.after)
            return
        self._set(value, ack, requests[0])
        if mode == "torque":
            self.joint.note_contact(got.after)

    def _wait_and_read(self, tick: float) -> tuple[list[JointState], float]:
        """The env's wait for ``tick`` (``RigEnv._wait_until`` -> ``Rig.sleep`` with no keep-alive due: the clock's
        sleep) and :meth:`state`, one after the other: (the state, what was left to the tick)."""
        clock = self.clock
        remaining = tick - clock.now()
        if remaining > 0:
            end = clock.now() + remaining
            now = clock.now()
            if end > now:
                clock.sleep(end - now)
        return [self.state()], remaining

    def _plain(self, names: tuple[str, ...]) -> bool:
        """Whether ``map.from_wire(name, raw)`` is ``raw`` for each of ``names`` (checked once per names and map):
        the stock ``CanMap.from_wire`` (and the lookups it calls, checked before every use) masks a ``uint32``
        parameter's raw value and multiplies by the key's scale; a parameter of another type with scale 1 gives
        ``raw * 1``, the same int. (The map's parameters and keys are frozen records: as the twin's exchange, this
        takes a name's type and scale as constants of its map.)"""
        cmap = self.access.map
        if type(cmap) is not CanMap or not _stock(_DECODE):
            return False
        seen, plain = self._plain_of
        if seen is not cmap:
            plain = set()
            self._plain_of = (cmap, plain)
        if names not in plain:
            if any(cmap.param(n).type == "uint32" or cmap.key(n).scale != 1 for n in names):
                return False
            plain.add(names)
        return True


def stepper(joint: Joint) -> ErobCanStep | None:
    """The compiled path's step of ``joint`` where it is an eRob on an eRob CAN link whose in-process peer (the
    medium's one device) offers a one-call exchange, else None."""
    driver = joint.driver
    if not isinstance(driver, ErobCanDriver) or not isinstance(driver.link, ErobCanLink):
        return None
    framing = driver.link.framing
    transport = getattr(framing, "transport", None)
    host = getattr(transport, "bus", None)
    peers: Any = getattr(getattr(host, "medium", None), "_peers", ())
    if not isinstance(framing, FrameFraming) or len(peers) != 1:
        return None
    make = getattr(peers[0].peer, "can_exchange", None)
    exchange = make(host, transport) if callable(make) else None
    return None if exchange is None else ErobCanStep(joint, driver, exchange)

