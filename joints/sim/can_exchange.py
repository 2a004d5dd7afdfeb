"""An eRob's steady CAN custom-protocol requests in one compiled call: frames, physics and the drive's ops.

Rule: it gives what the frame-by-frame path gives - the host's link over python-can's lockstep bus
(:class:`~joints.transports.can_sim.LockstepCanBus`: ``Link._drain``'s poll, ``submit``, ``receive`` and its
``_wait_until``/``_skippable`` over the :class:`~joints.transports.can_sim.CanMedium`), the world's clock
(``World.advance``: the due substeps, ``_until_event``, the bus's tick after them) and the twin
(:class:`~joints.sim.erob_can.ErobCanFront` on :class:`~joints.sim.erob.ErobFirmware`) - float by float:
the frame instants are the medium's own arithmetic on the fixed frame sizes (worst-case or no bit stuffing: a
frame's bits depend on its data length only), each ``max`` spelled as Python's builtin. Inside the call the
physics runs to the instant each request reaches the drive, and the drive acts through the kernel ops of
:mod:`joints.sim.erob_kernel` its firmware's own writes and reads call (``frame``, ``ready`` + ``start``, the
target's column, ``status`` / ``status_out``; the analog set-point 0x01FE as :meth:`ErobCanFront._setpoint`
makes it act: ``ready``, then ``target_speed`` or ``target_current``, or held where the motor is not ready);
afterwards Python brings the medium (its time, free instant, counters), the bus's last tick, the world and
clock, the firmware's parameter store and write log, the front's request count and held set-point and the
sensors (what a read of position, speed or current reports, in the order of the reads, where the call did not
make those reports itself at each read's act: :func:`report`) to where the frame-by-frame path leaves them, and
makes the replies (``ValueReply``, ``Ack``, the ``ErrorReply`` 0x0027 of a start that found the motor not ready,
which ends the call as it ends the host's move).

A set-point held inside the call: from then on the world ticks the bus every substep (``ErobCanBus.next_event``
is -inf) and each tick asks the drive ``ready()``. The call steps its substeps in stretches instead, which gives
the same bits only because nothing is left for those ticks to do: a set-point is sent only while the drive is
READY and goes alone, so a hold means a fault (or the watchdog) took the drive out of READY during the call, and
from there no substep makes it ready again (only an enable command does); the medium's ticks meanwhile only move
its last tick, which the call sets to the same final value.

A sleep the world held (``World.hold`` where the bus lets it: :func:`holds`, nothing in flight) runs first in the
next call, as ``World.sync`` would run it at the medium's first ``_sync``: its substeps, the bus's tick at the
last one's end (the medium's time moves there), the clock at the sleep's end. ``acks`` gives a command's outcome
without its ``Ack`` objects (the host proves once that its rule takes them). ``step`` carries an env's whole step:
the command's requests, the env's wait for its tick as the world holds it (a :data:`HOLD` row: :func:`hold`) and
the state reads - the held sleep then runs before the first read, inside the same call.

It runs only in the steady case, checked before anything is sent (:meth:`ErobCanExchange.run` returns None
otherwise): the world runs fused with this bus's tick its only tick, the medium times frames (not ideal,
stuffing not "exact"), nothing is on it, queued or waiting for the host, the host is the medium's only
python-can node and the bus its only peer, the methods the frames go through are the stock ones (a test
planting frames replaces one), no set-point is held, every write is one the firmware and the front accept
now (a nonzero set-point in speed or torque mode only while the drive is READY, and alone), and the clock is
far enough from 0 and the link's timeout long enough that none of the medium's branches for those cases can be
met. ``tests/sim/test_can_exchange.py`` compares both paths bit for bit.

Not mirrored: the bus's cache of decoded request frames and the front's caches of prepared reads (they
only save work; what they hold does not change what a request does).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from joints.codecs import erob_can as ec
from joints.devices.erob.can import EROB_CAN, Reach
from joints.devices.erob.registers import MotionMode, OperationMode
from joints.errors import ParameterRefused
from joints.sim import erob, kernel, sensors, stepping
from joints.sim import erob_can as sim_can
from joints.sim import erob_kernel as K
from joints.sim import line_exchange as L
from joints.sim.erob import ErobFirmware
from joints.sim.erob_can import ErobCanBus, ErobCanFront
from joints.sim.erob_kernel import fmax
from joints.sim.kernel import jitable
from joints.sim.sensors import Sensor
from joints.sim.stepping import STEPS
from joints.transports import can as can_transport
from joints.transports.can_sim import CanMedium, LockstepCanBus

__all__ = ["ErobCanExchange", "Stepped", "act", "exchanges", "hold", "holds"]

_SPEED, _TORQUE = int(OperationMode.SPEED), int(OperationMode.TORQUE)

#: columns of the state vector (the first three are :mod:`joints.sim.line_exchange`'s: ``L.fused`` brings the
#: world and clock back): the clock, the world's target time, booked; the medium's time, the clock time it last
#: saw, when the bus is free, its last tick; its frame, bit and busy-time counters; the world's timestep; ticks
#: made; the link's timeout; transactions done; whether a branch the call does not model was met; whether the
#: reads' sensor reports are made in the call (:func:`report`; cleared after one met a value that is not finite)
CLOCK, TARGET, BOOKED, NOW, SEEN, FREE, TICKED, FRAMES, BITS, BUSY, DT, TICKS, TIMEOUT, DONE, ODD, REPORTS = range(16)
STATE_WIDTH = 16
#: columns of a transaction row: the drive's row, the request's wire time and bits, the reply's, an error
#: reply's, the drive's answer delay, the host adapter's latency; the op and its arguments; a read's sensor report
ROW, REQ_TOOK, REQ_BITS, REP_TOOK, REP_BITS, ERR_TOOK, ERR_BITS, DELAY, LATENCY, OP, VALUE, MOTION, RELATIVE, \
    REPETITIVE, SENSE = range(15)
TX_WIDTH = 15
#: ops: a read (the status values of a copy of the row: no side effect), the read of
#: ``status_of_achieving_position`` (the row itself: its settle timer runs), the target write, "start", the
#: analog set-point 0x01FE (``analog_quantity_value``)
READ, READ_ACHIEVE, TARGET_POSITION, START, SETPOINT = range(5)
#: the op of a row that is no transaction but the host's wait for the env's tick (:func:`hold`): the tick in
#: :data:`UNTIL`; whether the last row (a read) is optional, and its rule's last read and period (:func:`hold`)
HOLD = 5
UNTIL, SINCE, PERIOD, OPTIONAL = VALUE, MOTION, RELATIVE, REPETITIVE
#: what a set-point write does (its MOTION column; :meth:`ErobCanFront._setpoint`): only stored (an external
#: analog source, or neither speed nor torque mode), the target speed, the target current
STORE, TO_SPEED, TO_CURRENT = 0.0, 1.0, 2.0
#: the parameter a set-point of each kind writes
SETPOINT_OF = {TO_SPEED: "target_speed", TO_CURRENT: "target_current"}
#: columns of an output row: the request's start and end, the reply's start and end, when the host has it, the
#: clock after; the reply refused (0x0027); the world's substeps when the drive acted; a set-point held (the
#: motor not ready); the status values; the row's columns the sensors see
E0, E1, R0, R1, HOST, CLOCK_AFTER, REFUSED, ACTED, HELD = range(9)
STATUS_AT = 9
SENSED = K.SENSED
SENSED_AT = STATUS_AT + len(K.STATUS_NAMES)
_SENSED = SENSED_AT - STATUS_AT  #: where the sensed columns start, counted from the status values
_TIME, _POS, _VEL, _I_OUT = SENSED  #: (in this order)
OUT_WIDTH = SENSED_AT + len(SENSED)
#: a :data:`HOLD` row's output: what was left to the tick (<= 0: late), the clock after (:data:`CLOCK_AFTER`),
#: whether the call got there, whether the optional last read is made
REMAINING, REACHED, MADE = E0, HOST, R0
#: a read's sensor report (its SENSE column; :func:`report`): none, the firmware's ``_sensed_counts``,
#: ``_sensed_speed``, ``_sensed_current`` (each into its status value), ``_sensed_at`` (the status read's: its
#: three values unused, its draws made; a value that is not finite goes into the read's own status value)
NO_REPORT, REPORT_POSITION, REPORT_SPEED, REPORT_CURRENT, REPORT_ALL = range(5)
_AT_POSITION, _AT_SPEED, _AT_CURRENT, _AT_ACHIEVE = (STATUS_AT + K.STATUS_NAMES.index(n) for n in (
    "actual_position", "current_speed", "motor_current", "status_of_achieving_position"))
_C = K.COUNTS_PER_RAD


@jitable
def act(s: Any, t: Any, o: Any, scratch: Any) -> bool:
    """The drive (row ``s``) acts on a request as :meth:`ErobCanFront.handle` makes its firmware act: its
    watchdog is fed, then the op; True: refused (a start while the motor is not ready: 0x0027, nothing
    latched). A set-point the motor is not ready for is held (``o[HELD]``: the front keeps it)."""
    K.frame(s)
    op = t[OP]
    o[HELD] = 0.0
    if op == READ or op == READ_ACHIEVE:
        r = s
        if op == READ:  # one value of the status: the status op on a copy (a generic read runs no settle timer)
            for k in range(s.shape[0]):
                scratch[k] = s[k]
            r = scratch
        K.status_out(s, r, t[REPETITIVE] != 0.0, o, STATUS_AT)
        return False
    if op == TARGET_POSITION:
        s[K.TARGET_ABSOLUTE] = t[VALUE]
        return False
    if op == SETPOINT:  # ErobCanFront._setpoint after the store (the firmware's write of 0x01FE acts on nothing)
        kind = t[MOTION]
        if kind != STORE:
            v = t[VALUE]
            if K.ready(s) or v == 0.0:
                if kind == TO_SPEED:
                    K.target_speed(s, v)
                else:
                    K.target_current(s, v)
            else:
                o[HELD] = 1.0
        return False
    if not K.ready(s):  # START
        return True
    K.start(s, t[MOTION], t[RELATIVE], t[VALUE])
    return False


@jitable
def report(s: Any, t: Any, o: Any, st: Any, sensor: Any, m: Any) -> None:
    """The read ``t``'s sensor report where the call makes them (``st[REPORTS]``), as the firmware's
    ``_sensed_counts``, ``_sensed_speed``, ``_sensed_current`` or ``_sensed_at`` makes it from the row as the read
    saw it (``o``'s sensed columns) with the sensor's rows (``sensor``: its state, the stream first; ``m``: its
    model's numbers) and the drive's row ``s`` (its position offset): the same draws, the same floats, the value
    (rounded as ``round``) into the read's status value. A value that is not finite goes there as it is (the host's
    ``int`` of it raises as the firmware's ``round`` would) and no later read of the call reports (Python stops
    there)."""
    kind = t[SENSE]
    if kind == NO_REPORT or st[REPORTS] == 0.0:
        return
    time, pos, vel, i = o[SENSED_AT], o[SENSED_AT + 1], o[SENSED_AT + 2], o[SENSED_AT + 3]
    if kind == REPORT_POSITION:
        x = sensors.position(sensor, m, time, pos / _C, vel / _C) * _C
        at = _AT_POSITION
    elif kind == REPORT_SPEED:
        x = sensors.velocity(sensor, m, pos / _C, vel / _C) * _C
        at = _AT_SPEED
    elif kind == REPORT_CURRENT:
        x = sensors.current(sensor, m, i * 1e-3) * 1e3
        at = _AT_CURRENT
    else:  # the status read's: the first of its three values that is not finite, if any
        p, v, c = sensors.sense(sensor, m, time, pos / _C, vel / _C, i * 1e-3)
        at = _AT_ACHIEVE
        x = 0.0
        for y in (p * _C, v * _C, c * 1e3):
            if not math.isfinite(y):
                x = y
                break
        if math.isfinite(x):
            return
    if not math.isfinite(x):
        o[at] = x
        st[REPORTS] = 0.0
    elif abs(x) >= 4503599627370496.0:  # (2**52) an integer already, past any register with any offset: the host
        o[at] = x  # saturates it as it saturates round(x) + offset
    else:
        v = float(K.round_half_even(x))
        o[at] = v + float(int(s[K.OFFSET])) if kind == REPORT_POSITION else v  # (exact: both < 2**52)


@jitable
def _due(seconds: float, st: Any, w: int, worlds: Any) -> int:
    """``World._due``: book ``seconds`` on the world's target, the substeps now due."""
    st[TARGET] += seconds
    dt = st[DT]
    return math.ceil((st[TARGET] - worlds[w, STEPS] * dt) / dt - 1e-9)  # type: ignore[no-any-return]


@jitable
def _until(e: float, n: int, st: Any, w: int, worlds: Any) -> int:
    """``World._until_event(n)`` with the medium announcing ``e``."""
    dt = st[DT]
    s = worlds[w, STEPS]
    if e <= (s + 1) * dt:
        return 1
    k = max(1, math.ceil(e / dt) - s)
    while k > 1 and (s + k - 1) * dt >= e:
        k -= 1
    while (s + k) * dt < e:
        k += 1
    return int(min(k, n))


@jitable
def _steps(n: int, st: Any, w: int, mj_step: int, table: Any, adr: Any, ratio: Any, order: Any, worlds: Any,
           dts: Any, active: Any) -> None:
    """``n`` substeps, then the bus's tick (``World._tick_now``: the medium's and the bus's last tick)."""
    if n > 0:
        stepping._run(n, 1, mj_step, table, adr, ratio, order, worlds, dts, active)
        worlds[w, STEPS] += n
        st[TICKED] = worlds[w, STEPS] * st[DT]
        st[TICKS] += 1.0


@jitable
def run_held(st: Any, w: int, mj_step: int, table: Any, adr: Any, ratio: Any, order: Any, worlds: Any, dts: Any,
             active: Any) -> None:
    """A sleep the world held (``World.hold``), run as ``World.sync`` runs it at the medium's first ``_sync``: its
    substeps, the bus's tick at the last one's end (the medium's, with no wait of its own: its time moves there),
    the clock at the sleep's end."""
    st[BOOKED] = 0.0
    n = _due(0.0, st, w, worlds)
    _steps(n, st, w, mj_step, table, adr, ratio, order, worlds, dts, active)
    t = st[TICKED]
    if n > 0 and t > st[NOW]:  # CanMedium.tick
        st[NOW] = t
        st[SEEN] = fmax(st[SEEN], t)
    st[CLOCK] = st[TARGET]


@jitable
def hold(t: Any, st: Any, o: Any, w: int, mj_step: int, table: Any, adr: Any, ratio: Any, order: Any, worlds: Any,
         dts: Any, active: Any) -> bool:
    """A :data:`HOLD` row ``t``: the env's wait for its tick at clock time ``t[UNTIL]`` (``RigEnv._wait_until``:
    ``remaining`` left, if > 0 the rig's sleep of it - ``Rig.sleep`` with no keep-alive due, ``end - now`` from
    ``end = now + remaining`` - as ``World.hold`` books it where the bus holds it: an earlier held sleep run first,
    as ``World._defer`` syncs it). Into ``o``: what was left, the clock after, reached. Returns whether the
    optional last read is made (``t[OPTIONAL]``: ``ErobCanDriver.state_names`` at the clock after: its last read
    ``t[SINCE]`` ago by at least ``t[PERIOD]``, or after now)."""
    now = st[CLOCK]
    remaining = t[UNTIL] - now
    o[REMAINING] = remaining
    if remaining > 0:
        end = now + remaining
        if end > now:
            if st[BOOKED] == L.HELD:
                run_held(st, w, mj_step, table, adr, ratio, order, worlds, dts, active)
            st[TARGET] += end - now
            st[BOOKED] = L.HELD
            st[CLOCK] = st[TARGET]
    t0 = st[CLOCK]
    o[CLOCK_AFTER] = t0
    o[REACHED] = 1.0
    made = t[OPTIONAL] == 0.0 or t0 - t[SINCE] >= t[PERIOD] or t0 < t[SINCE]
    o[MADE] = 1.0 if made else 0.0
    return made  # type: ignore[no-any-return]


@jitable
def held_setpoint(out: Any, k: int) -> bool:
    """Whether a set-point of the rows before ``k`` was held by the front (``out``'s HELD)."""
    for i in range(k):
        if out[i, HELD] != 0.0:
            return True
    return False


@jitable
def _wait(until: float, st: Any, w: int, mj_step: int, table: Any, adr: Any, ratio: Any, order: Any, worlds: Any,
          dts: Any, active: Any) -> None:
    """``ClockDriven._wait_until(until)`` with nothing due on the medium: the clock sleeps (``World.advance``)."""
    behind = until - st[CLOCK]
    if behind > 0:
        st[BOOKED] = 0.0
        _steps(_due(behind, st, w, worlds), st, w, mj_step, table, adr, ratio, order, worlds, dts, active)
        st[CLOCK] = st[TARGET]
        st[SEEN] = st[CLOCK]
    st[NOW] = fmax(st[NOW], until)


def exchanges(tx: Any, out: Any, scratch: Any, sensor: Any, m: Any, st: Any, w: int, mj_step: int, table: Any,
              adr: Any, ratio: Any, order: Any, worlds: Any, dts: Any, active: Any) -> None:
    """The transactions ``tx`` in world ``w`` one after the other, as the host's link carries each over the
    lockstep medium: ``st`` in and out, each one's instants (and its read's values, with their sensor reports
    where ``st[REPORTS]``: :func:`report` with the sensor's rows ``sensor`` and ``m``) into ``out``. Stops after a
    refused request; ``st[ODD]`` set: a branch of the medium the call does not model was met (the caller's
    checks keep it from happening). A sleep the world held (``st[BOOKED]`` is ``L.HELD``: ``World.hold``) runs
    first, as ``World.sync`` runs it at the medium's first ``_sync`` (:func:`run_held`). A :data:`HOLD` row is the
    host's wait for the env's tick between two requests (:func:`hold`; the call stops there where a set-point
    before it was held: the world then does not hold the sleep)."""
    count = tx.shape[0]
    k = -1
    while k + 1 < count:
        k += 1
        t = tx[k]
        o = out[k]
        if t[OP] == HOLD:
            if held_setpoint(out, k):  # the world cannot hold the sleep (the bus ticks): Python goes on from here
                return
            if not hold(t, st, o, w, mj_step, table, adr, ratio, order, worlds, dts, active):
                count -= 1  # the optional last read is not made
            continue
        if st[BOOKED] == L.HELD:
            run_held(st, w, mj_step, table, adr, ratio, order, worlds, dts, active)
        # Link._drain: receive(host, 0.0): the medium's _sync, then the poll (a wait until the medium's time
        # where the clock is behind it)
        c = st[CLOCK]
        if c > st[SEEN]:
            st[SEEN] = c
            st[NOW] = fmax(st[NOW], c)
        if not c >= st[NOW]:
            _wait(st[NOW], st, w, mj_step, table, adr, ratio, order, worlds, dts, active)
        # the request: submit (the medium's _sync, then on the bus at once: it is free)
        deadline = st[CLOCK] + st[TIMEOUT]
        c = st[CLOCK]
        if c > st[SEEN]:
            st[SEEN] = c
            st[NOW] = fmax(st[NOW], c)
        start = fmax(st[FREE], st[NOW])
        if start > st[NOW]:
            st[ODD] = 1.0
            return
        end = start + t[REQ_TOOK]
        st[FRAMES] += 1.0
        st[BITS] += t[REQ_BITS]
        st[BUSY] += t[REQ_TOOK]
        o[E0] = start
        o[E1] = end
        # receive(host, timeout): FrameFraming's and LockstepCanBus's timeouts, the medium's deadline
        left = fmax(deadline - st[CLOCK], 0.0)
        left = fmax(st[NOW] + fmax(left, 0.0) - st[NOW], 0.0)
        limit = st[NOW] + fmax(left, 0.0)
        if not end < limit:
            st[ODD] = 1.0
            return
        # the request's end: processed at once where the physics stands past it (_skippable), else waited for
        acted_at = -1.0
        s = table[int(t[ROW])]
        if end <= 2.0 * st[CLOCK] and end <= st[TICKED]:
            refused = act(s, t, o, scratch)
            report(s, t, o, st, sensor, m)
        else:
            behind = end - st[CLOCK]
            acted = False
            refused = False
            if behind > 0:
                st[BOOKED] = 0.0
                n = _due(behind, st, w, worlds)
                if n > 0:
                    j = _until(end, n, st, w, worlds)
                    if j < n:  # the tick after j substeps reaches the frame's end: the drive acts there
                        _steps(j, st, w, mj_step, table, adr, ratio, order, worlds, dts, active)
                        refused = act(s, t, o, scratch)
                        report(s, t, o, st, sensor, m)
                        acted = True
                        acted_at = worlds[w, STEPS]
                        n -= j
                    _steps(n, st, w, mj_step, table, adr, ratio, order, worlds, dts, active)
                st[CLOCK] = st[TARGET]
                st[SEEN] = st[CLOCK]
            if not acted:
                refused = act(s, t, o, scratch)
                report(s, t, o, st, sensor, m)
            st[NOW] = fmax(st[NOW], end)
        o[REFUSED] = 1.0 if refused else 0.0
        o[ACTED] = worlds[w, STEPS] if acted_at < 0 else acted_at
        took = t[ERR_TOOK] if refused else t[REP_TOOK]
        # the reply: queued after the drive's delay, on the bus when it is free (each edge processed without a
        # wait: the peers only answer and the reply reaches no peer)
        st[FREE] = end
        begin = fmax(end, end + t[DELAY])
        finish = begin + took
        st[FRAMES] += 1.0
        st[BITS] += t[ERR_BITS] if refused else t[REP_BITS]
        st[BUSY] += took
        if not (finish < limit and finish <= 2.0 * st[CLOCK]):
            st[ODD] = 1.0
            return
        st[FREE] = finish
        o[R0] = begin
        o[R1] = finish
        seen = finish
        if t[LATENCY] > 0:  # the host adapter holds the frame that long; the host waits for it
            seen = finish + t[LATENCY]
            if seen <= st[NOW] + 1e-12 or not seen < limit or seen > 2.0 * st[CLOCK]:
                st[ODD] = 1.0
                return
        _wait(seen, st, w, mj_step, table, adr, ratio, order, worlds, dts, active)
        o[HOST] = seen
        o[CLOCK_AFTER] = st[CLOCK]
        st[DONE] += 1.0
        if refused:
            return


_COMPILED: list[Any] = []


def _compiled() -> Any:
    """:func:`exchanges` compiled (numba), or None without it (with ``JOINTS_COMPILED=0`` the world does not run
    fused: the steady checks send the requests frame by frame)."""
    if not _COMPILED:
        ok = kernel.AVAILABLE and stepping._run_compiled is not None
        _COMPILED.append(kernel.compiled(exchanges) if ok else None)
    return _COMPILED[0]


#: the methods the frames would go through, as defined (captured when this module is imported): a replaced one
#: means no one-call exchange
_STOCK = (*erob.STOCK, *((cls, name, getattr(cls, name)) for cls, names in (
    (CanMedium, ("submit", "receive", "tick", "next_event", "_run", "_sync", "_deliver", "_deliver_to_all",
                 "_skippable", "_next_event", "_wait_until", "_bits", "_enqueue", "time")),
    (LockstepCanBus, ("send", "recv", "_matches_filters")),
    (can_transport.PythonCanTransport, ("send", "recv")),
    (ErobCanBus, ("on_frame", "exchange", "front", "turnaround", "tick", "next_event")),
    (ErobCanFront, ("handle", "_read", "_write", "_command", "_setpoint", "_fw_read", "tick")),
    (erob._StatusRead, ("finish",)),
    (ErobFirmware, ("_sensed", "_sensed_at", "_sensed_counts", "_sensed_speed", "_sensed_current", "offset")),
    (Sensor, ("position", "velocity", "current", "sense")),
) for name in names))


#: what a held sleep rests on (:func:`holds`): the medium's entries that settle the world first (``_sync``), its
#: ticks and waits, the host's frames
_HOLD_STOCK = tuple((cls, name, getattr(cls, name)) for cls, names in (
    (CanMedium, ("_sync", "tick", "next_event", "_next_event", "receive", "submit", "send_at", "time", "load",
                 "reset_load", "_wait_until")),
    (LockstepCanBus, ("send", "recv")),
    (ErobCanBus, ("tick", "next_event", "holds")),
) for name in names)


def holds(bus: ErobCanBus) -> bool:
    """Whether the world may hold a sleep with ``bus`` ticking (``World.hold``): its substeps and the bus's tick
    run later - at the medium's next ``_sync`` (a frame sent or received, its time or load asked), at the next
    one-call exchange (which runs them first) or at any access to the physics (``World.sync``) - the same as at
    the sleep, since until then nothing reaches the medium or the drives. Held only where the bus's ticks would
    do nothing but move its time over the sleep and the medium is not sleeping the clock itself (``_cap``: a wait
    of its own is never held): nothing on the wire, queued, being delivered or waiting for a node, no set-point
    held by a front; the methods that settle and tick, stock."""
    medium = bus.medium
    if medium._cap is not None or medium._wire is not None or medium._pending or medium._delivering is not None:
        return False
    for n in medium._nodes:
        if n.rx or n.held:
            return False
    for f in bus.fronts:
        if f.held is not None:
            return False
    return L.stock(_HOLD_STOCK)


#: the reads whose value the drive's sensors report (the firmware's method, given the row as the read saw it)
_SENSED_READS = {"actual_position": "_sensed_counts", "current_speed": "_sensed_speed",
                 "motor_current": "_sensed_current"}
#: their reports made in the call (:func:`report`)
_REPORT_OF = {"actual_position": REPORT_POSITION, "current_speed": REPORT_SPEED, "motor_current": REPORT_CURRENT}


def _direct(plan: Any) -> tuple[int, int, int] | None:
    """Where a prepared status read of one value (``ErobFirmware.reader``) finds it and its saturation, where its
    ``finish`` (stock, checked before every call) gives that value as its status value saturated, after the
    sensors' report whose values it does not use (the value is none of the three they report); else None."""
    if type(plan) is not erob._StatusRead or len(plan.entries) != 1:
        return None
    ((at, _name, lo, hi),) = plan.entries
    if at < 0 or at in (erob._SENSED_COUNTS, erob._SENSED_SPEED, erob._SENSED_CURRENT):
        return None
    return at, lo, hi


@dataclass(frozen=True, slots=True)
class Stepped:
    """What :meth:`ErobCanExchange.step` did: the commands done, the refused start's error reply (the last done) or
    None, the clock after the commands; then (what was left to the tick, the clock after the wait, the reads'
    values - one fewer where the optional last read was not made), or None where the call stopped before."""

    done: int
    refusal: Any
    after: float
    read: tuple[float, float, list[int]] | None


@dataclass(frozen=True, slots=True)
class _Shape:
    """What requests of one shape (kind, index, subindex) have in common."""

    op: int
    name: str  #: the parameter
    request: tuple[int, float]  #: the request frame's bits and wire time
    reply: tuple[int, float]  #: the plain reply's
    error: tuple[int, float]  #: an error reply's
    extra: Any  #: a read: (status index, scale, lo, hi, the prepared status read or None, its :func:`_direct`)
    sense: int = NO_REPORT  #: a read's sensor report (:func:`report`); -1: one the call cannot make


@dataclass(frozen=True, slots=True)
class _Plan:
    """The transaction rows of some requests, and what the steady checks need of them."""

    requests: Sequence[Any]
    shapes: list[_Shape]
    fronts: list[ErobCanFront]
    unique: tuple[ErobCanFront, ...]  #: the fronts, each once
    tx: Any  #: the rows (an array)
    span: float  #: s the transactions take at most, together
    longest: float  #: s one of them takes at most
    stamp: tuple[Any, ...]  #: :meth:`ErobCanExchange._stamp` of its fronts (each once) when it was made
    reads: bool  #: reads only
    reports: bool  #: reads with sensor reports, each one the call can make, of one front


class ErobCanExchange:
    """The steady requests of the eRob twins on ``bus`` (an :class:`ErobCanBus`) from the host node ``host`` (a
    :class:`LockstepCanBus` on its medium, the link's ``transport``), in ``world`` (see the module docstring)."""

    def __init__(self, world: Any, bus: ErobCanBus, host: LockstepCanBus, transport: Any) -> None:
        import numpy as np

        self.world = world
        self.bus = bus
        self.medium: CanMedium = bus.medium
        self.host = host
        self.transport = transport
        self.taken = 0  #: calls that ran
        self._last: Any = np.zeros((0, OUT_WIDTH))  #: the output rows of the last :meth:`run` (its first ``_done``)
        self._done = 0
        self._hold = -1  #: the hold row of the last call's rows (:meth:`step`), or -1
        self._st = np.zeros(STATE_WIDTH)
        self._out: dict[int, Any] = {}  #: output rows per count
        self._plans: dict[int, _Plan] = {}  #: id of a tuple of reads -> its plan
        self._scratch: dict[int, Any] = {}  #: a row's copy (per table width)
        self._shapes: dict[tuple[Any, ...], _Shape | None] = {}
        self._rows: dict[int, tuple[Any, int]] = {}  #: node -> (group, its row there)
        #: the requests' shapes (kind, node, index, subindex, parameter per request) -> the plan last made for them
        #: with a write or command among them (a command: its rows but a few columns are the same every step)
        self._commands: dict[tuple[Any, ...], _Plan] = {}
        self.refilled = 0  #: plans made from a kept command plan (:meth:`_refill`)
        self.setpoints = 0  #: set-point writes (speed or current) carried
        self.held = 0  #: of them, held by the front (the drive stopped being ready during the call)
        self.sleeps = 0  #: calls that ran a sleep the world held first (``World.hold``; :func:`holds`)
        self._row_seen: dict[int, float] = dict.fromkeys(SENSED, 0.0)  #: :meth:`_sensed_row`'s
        self._reported = False  #: the last call made its reads' sensor reports (:meth:`_reporting`)
        self.reported = 0  #: calls that made their reads' sensor reports
        self._none = np.zeros(1)  #: the sensor rows given to a call that makes no reports
        #: the rows of a step and its output rows (:meth:`_joined`) per sizes
        self._steps_tx: dict[tuple[int, int], tuple[Any, Any]] = {}
        self.steps = 0  #: env steps carried whole (:meth:`step`: the command, the wait and the read)

    # -- the steady case ------------------------------------------------------------------------
    def _steady(self, front: ErobCanFront) -> bool:
        """Whether the world, medium, host, bus, front and firmware are as the compiled call assumes."""
        world, medium, bus, host = self.world, self.medium, self.bus, self.host
        group = world.group
        if not (group.compiled and group.fusable[world.group_index]) or world._bind != world._bind_seen or \
                (world._booked and not world._held) or world._target != world.clock.now():
            return False
        if world._ticks != [bus.tick] or world._bus_watches or len(world._events or ()) != 1:
            return False
        if medium.ideal or medium.stuffing == "exact" or medium.clock is not world.clock or medium._cap is not None:
            return False
        if medium._wire is not None or medium._pending or medium._delivering is not None or not medium.answers_only:
            return False
        if medium._epoch_seen != getattr(world.clock, "epoch", None) or medium._free > medium.now:
            return False
        node = host._node
        if len(medium._peers) != 1 or medium._peers[0].peer is not bus or len(medium._nodes) != 2 or \
                node not in medium._nodes or node.rx or node.held or node.receive_own:
            return False
        if type(host) is not LockstepCanBus or host._is_shutdown or host._filters or \
                type(self.transport) is not can_transport.PythonCanTransport or self.transport.bus is not host or \
                self.transport._closed or self.transport.echoes:
            return False
        if type(bus) is not ErobCanBus or front not in bus.fronts or any(f.held is not None for f in bus.fronts):
            return False
        fw = front.firmware
        if type(front) is not ErobCanFront or type(fw) is not ErobFirmware or fw.pending or fw.command_delay > 0:
            return False
        return L.stock(_STOCK)

    def _shape(self, request: Any, front: ErobCanFront) -> _Shape | None:
        kind = type(request)
        key = (kind, request.node, request.index, getattr(request, "subindex", None),
               getattr(request, "parameter", None))
        shapes = self._shapes
        if key not in shapes:
            shapes[key] = self._make_shape(request, front)
        return shapes[key]

    def _timed(self, message: Any) -> tuple[int, float]:
        frame = ec.encode(message)
        bits = self.medium._bits(frame)  # (kept in the medium's cache, as the frame-by-frame path keeps it)
        return bits, bits / self.medium.bitrate

    def _make_shape(self, request: Any, front: ErobCanFront) -> _Shape | None:
        fw = front.firmware
        node = request.node
        error = self._timed(ec.ErrorReply(node, sim_can.START_WHILE_OFF))
        if type(request) is ec.Read:
            try:
                name = EROB_CAN.at(request.index, request.subindex)
            except KeyError:
                return None
            key = EROB_CAN.key(name)
            if key.reach is not Reach.VALUE or not EROB_CAN.access(name).readable or name not in K.STATUS_NAMES or \
                    request.index == 0x0232:
                return None
            if fw.computed.get(name) is not fw._own_computed.get(name):
                return None
            lo, hi = fw._type_range[name]
            plan = fw.reader((name,)) if name == "status_of_achieving_position" else None
            if plan is not None and not isinstance(plan, erob._StatusRead):
                return None
            op = READ_ACHIEVE if plan is not None else READ
            direct = _direct(plan)
            sense = _REPORT_OF.get(name, NO_REPORT) if plan is None else REPORT_ALL if direct is not None else -1
            return _Shape(op, name, self._timed(request), self._timed(ec.ValueReply(node, 0)), error,
                          (K.STATUS_NAMES.index(name), key.scale, lo, hi, plan, direct), sense)
        if type(request) is ec.Write and request.subindex is None:
            try:
                name = EROB_CAN.at(request.index, None)
            except KeyError:
                return None
            if name not in ("target_absolute_position", "analog_quantity_value"):
                return None
            key = EROB_CAN.key(name)
            if key.reach is not Reach.VALUE or not EROB_CAN.access(name).writable:
                return None
            op = TARGET_POSITION if name == "target_absolute_position" else SETPOINT
            return _Shape(op, name, self._timed(request), self._timed(ec.Ack(node)), error, None)
        if type(request) is ec.Command and request.parameter is None and request.index == 0x0083:
            return _Shape(START, "start_operating", self._timed(request), self._timed(ec.Ack(node)), error, None)
        return None

    def _row(self, front: ErobCanFront) -> int:
        group = self.world.group
        got = self._rows.get(front.node)
        if got is None or got[0] is not group:
            fw = front.firmware
            got = self._rows[front.node] = (group, next(first for twin, first in group._owners if twin is fw))
        return got[1]

    def _tx(self, request: Any, front: ErobCanFront, target: dict[str, int]) -> tuple[list[float], _Shape] | None:
        """The transaction row of ``request``, or None where it is not a steady one now."""
        shape = self._shape(request, front)
        if shape is None:
            return None
        fw = front.firmware
        values = fw.values
        delay = self.bus.turnarounds.get(front.node)
        delay = self.medium._peers[0].latency if delay is None else delay
        value = 0.0
        motion = relative = repetitive = 0.0
        if shape.op == TARGET_POSITION:
            v = EROB_CAN.from_wire(shape.name, request.value)
            writable, lo, hi = fw._limits[shape.name]
            if not writable or type(v) is not int or not lo <= v <= hi:
                return None
            target[shape.name] = v
            value = float(v)
        elif shape.op == SETPOINT:
            got = self._setpoint(fw, request)
            if got is None:
                return None
            value, motion = got
        elif shape.op == START:
            if values["motion_mode"] not in tuple(MotionMode):
                return None
            writable, lo, hi = fw._limits["start_operating"]
            if not writable or not lo <= 1 <= hi:
                return None
            value = float(target.get("target_absolute_position", values["target_absolute_position"]))
            motion = float(values["motion_mode"])
            relative = float(values["target_relative_position"])
        else:
            repetitive = 1.0 if values["motion_mode"] == int(MotionMode.REPETITIVE) else 0.0
        req, rep, err = shape.request, shape.reply, shape.error
        return [float(self._row(front)), req[1], float(req[0]), rep[1], float(rep[0]), err[1], float(err[0]),
                delay, self.host._node.latency, float(shape.op), value, motion, relative, repetitive,
                float(max(shape.sense, NO_REPORT))], shape

    @staticmethod
    def _setpoint(fw: ErobFirmware, request: Any) -> tuple[float, float] | None:
        """A set-point write's value and kind (what :meth:`ErobCanFront._write` and ``_setpoint`` do with it), or
        None where it is not a steady request now: a value the firmware refuses (for 0x01FE or for the target it
        sets), or a nonzero target while the drive is not READY (the call models a set-point held from then on
        only where the drive cannot become ready during it: from READY only a fault leaves, and no command
        comes back)."""
        name = "analog_quantity_value"
        v = EROB_CAN.from_wire(name, request.value)
        writable, lo, hi = fw._limits[name]
        if not writable or type(v) is not int or not lo <= v <= hi:
            return None
        values = fw.values
        mode = values["operation_mode"]
        if values["analog_quantity_type"] != 0 or mode not in (_SPEED, _TORQUE):
            return float(v), STORE
        target = "target_speed" if mode == _SPEED else "target_current"
        writable, lo, hi = fw._limits[target]
        if not writable or not lo <= v <= hi:
            return None
        try:
            fw.check_write(target, v)
        except ParameterRefused:
            return None
        if v != 0 and fw._row[K.STATE] != K.READY:
            return None
        return float(v), TO_SPEED if mode == _SPEED else TO_CURRENT

    # -- the call -------------------------------------------------------------------------------
    def _plan(self, requests: Sequence[Any]) -> _Plan | None:
        """The transaction rows of ``requests`` now, or None where one is not a steady request now. Kept: a tuple
        of reads (it is sent again and again), and the rows of a command's shapes (:meth:`_refill` puts each
        request's own columns into them)."""
        plan = self._plans.get(id(requests))
        if plan is not None and plan.requests is requests and plan.stamp == self._stamp(plan.unique):
            return plan
        key = tuple([(type(r), r.node, r.index, getattr(r, "subindex", None), getattr(r, "parameter", None))
                     for r in requests])
        plan = self._commands.get(key)
        if plan is not None and plan.stamp == self._stamp(plan.unique):
            self.refilled += 1
            return plan if self._refill(plan, requests) else None
        plan = self._fresh(requests)
        if plan is None or plan.reads:
            return plan
        if len(self._commands) > 64:
            self._commands.clear()
        self._commands[key] = plan
        return plan

    def _refill(self, plan: _Plan, requests: Sequence[Any]) -> bool:
        """``plan`` (kept for requests of these shapes, its stamp still holding) made the plan of ``requests``: the
        columns that depend on the request or on parameters outside the stamp (a target's value, a start's target
        and relative position) as :meth:`_tx` makes them; False where one is not a steady request now."""
        tx = plan.tx
        targets: dict[int, int] = {}
        for k, (r, shape, front) in enumerate(zip(requests, plan.shapes, plan.fronts)):
            if front.node != r.node:  # (a node id changed at a power cycle)
                return False
            op = shape.op
            fw = front.firmware
            if op == TARGET_POSITION:
                v = EROB_CAN.from_wire(shape.name, r.value)
                writable, lo, hi = fw._limits[shape.name]
                if not writable or type(v) is not int or not lo <= v <= hi:
                    return False
                targets[r.node] = v
                tx[k, VALUE] = float(v)
            elif op == SETPOINT:
                got = self._setpoint(fw, r)
                if got is None:
                    return False
                tx[k, VALUE], tx[k, MOTION] = got
            elif op == START:  # (the motion mode is in the stamp: its check and column hold)
                writable, lo, hi = fw._limits["start_operating"]
                if not writable or not lo <= 1 <= hi:
                    return False
                values = fw.values
                tx[k, VALUE] = float(targets.get(r.node, values["target_absolute_position"]))
                tx[k, RELATIVE] = float(values["target_relative_position"])
        return True

    def _fresh(self, requests: Sequence[Any]) -> _Plan | None:
        """The plan of ``requests`` made row by row (:meth:`_tx`); a tuple of reads kept by its identity."""
        bus = self.bus
        rows: list[list[float]] = []
        shapes: list[_Shape] = []
        fronts: list[ErobCanFront] = []
        targets: dict[int, dict[str, int]] = {}
        for r in requests:
            front = bus.front(r.node)
            if front is None:
                return None
            got = self._tx(r, front, targets.setdefault(r.node, {}))
            if got is None:
                return None
            rows.append(got[0])
            shapes.append(got[1])
            fronts.append(front)
        if len(shapes) > 1 and any(s.op == SETPOINT for s in shapes):
            return None  # a set-point goes alone (one it holds changes how the world ticks for what follows)
        import numpy as np

        dt = self.world.timestep
        spans = [t[REQ_TOOK] + t[DELAY] + max(t[REP_TOOK], t[ERR_TOOK]) + t[LATENCY] + 2.0 * dt for t in rows]
        unique = tuple(dict.fromkeys(fronts))
        reads = all(s.op in (READ, READ_ACHIEVE) for s in shapes)
        senses = [s.sense for s in shapes]
        reports = len(unique) == 1 and any(senses) and min(senses) >= 0
        plan = _Plan(requests, shapes, fronts, unique, np.array(rows), sum(spans) + dt, max(spans),
                     self._stamp(unique), reads, reports)
        if reads and isinstance(requests, tuple):
            if len(self._plans) > 64:
                self._plans.clear()
            self._plans[id(requests)] = plan
        return plan

    def _stamp(self, fronts: Sequence[ErobCanFront]) -> tuple[Any, ...]:
        """What a kept plan's rows depend on besides its requests: the table, the fronts' node ids (one changes at
        a power cycle), the motion modes, the delays (``fronts``: a plan's, each once)."""
        turnarounds = self.bus.turnarounds
        return (self.world.group, self.medium._peers[0].latency, self.host._node.latency,
                tuple((f.node, f.firmware.values["motion_mode"], turnarounds.get(f.node)) for f in fronts))

    def _call(self, requests: Sequence[Any], timeout: float, reads: bool) -> tuple[_Plan, Any, int] | None:
        """The compiled call of ``requests`` (the world's lock held) and the medium brought back: the plan, the
        output rows and how many transactions were done; None (nothing sent) where this is not the steady case
        (or ``reads`` and a request is not a read)."""
        fn = _compiled()
        if fn is None or not requests:
            return None
        plan = self._plan(requests)
        if plan is None or (reads and not plan.reads):
            return None
        got = self._carry(fn, plan.tx, plan, plan.span, plan.longest, timeout, False)
        if got is None:
            return None
        out, done = got
        self._last, self._done, self._hold = out, done, -1
        return plan, out, done

    def _carry(self, fn: Any, tx: Any, plan: _Plan, span: float, longest: float, timeout: float, hold: bool,
               out: Any = None) -> tuple[Any, int] | None:
        """The compiled call of the rows ``tx`` (the world's lock held; ``plan``: whose fronts they are for and
        whose reads' sensor reports the call makes; ``span``, ``longest``: the rows' time at most, together and
        one; ``hold``: a :data:`HOLD` row among them; ``out``: the output rows, else a buffer per size) and the
        medium brought back: the output rows and how many transactions were done; None (nothing sent) where this
        is not the steady case."""
        for front in plan.unique:
            if not self._steady(front):
                return None
        world, medium, bus = self.world, self.medium, self.bus
        clock = world.clock.now()
        held = world._booked  # (a held sleep: _steady) its substeps run first, the medium's time up to a step past
        ahead = max(medium.now - clock, 0.0) + (world.timestep if held or hold else 0.0)
        # the branches of the medium the call does not model (a frame within twice the clock's time of 0, a reply
        # near the link's timeout) cannot be met: the whole call is well inside both
        if not clock > 2.0 * (span + ahead) or not longest < 0.5 * timeout:
            return None
        n = len(tx)
        if out is None:
            out = self._out.get(n)
            if out is None:
                import numpy as np

                out = self._out[n] = np.zeros((n, OUT_WIDTH))
        sensor = self._reporting(plan)
        self._reported = sensor is not None
        self.reported += self._reported
        st = self._st
        st[:] = (clock, world._target, L.HELD if held else 0.0, medium.now, medium._clock_seen, medium._free,
                 medium._ticked,
                 0.0, 0.0, medium.busy, world.timestep, 0.0, timeout, 0.0, 0.0, 1.0 if self._reported else 0.0)
        scratch = self._scratch.get(world.group.table.shape[1])
        if scratch is None:
            import numpy as np

            scratch = self._scratch[world.group.table.shape[1]] = np.zeros(world.group.table.shape[1])
        if sensor is None:
            state = L.fused(fn, world, st, tx, out, scratch, self._none, self._none)
        else:
            state = L.fused(fn, world, st, tx, out, scratch, sensor.state, sensor._m)
        medium.now = state[NOW]
        medium._clock_seen = state[SEEN]
        medium._free = state[FREE]
        done = int(state[DONE])
        frames = int(state[FRAMES])
        medium.frames += frames
        medium.bits += int(state[BITS])
        medium.busy = state[BUSY]
        medium._seq = itertools.count(next(medium._seq) + frames)
        if state[TICKS]:
            medium._ticked = bus._last_tick = state[TICKED]
        if state[ODD] or done == 0:
            raise RuntimeError(f"{bus.medium.channel}: the one-call exchange met a branch it does not model "
                               f"after {done} of {n} requests; this is a bug (the steady checks let it through)")
        self.taken += 1
        if held:
            self.sleeps += 1
        return out, done

    def step(self, commands: Sequence[Any], until: float, reads: tuple[Any, ...], timeout: float,
             since: float | None, period: float) -> Stepped | None:
        """An env step's requests in one call: ``commands`` (writes and commands, as :meth:`acks` sends them), the
        host's wait for the env's tick at clock time ``until`` (:func:`hold`: ``RigEnv._wait_until`` with the rig's
        sleep the world's hold - the bus holds it: :func:`holds`), then ``reads`` (a tuple of reads, as
        :meth:`values` sends them; ``since`` not None: the last is made only where the clock after the wait is at
        least ``period`` past ``since``, or before it - ``ErobCanDriver.state_names``). None (nothing sent) where
        this is not the steady case. The call stops after a refused start, or before the wait where a set-point
        was held (the bus ticks then: the world does not hold the sleep; the caller waits and reads)."""
        for r in commands:
            if type(r) is ec.Read:
                return None
        fn = _compiled()
        if fn is None or not commands or not reads:
            return None
        with self.world.lock:
            if not L.sleeps_held(self.world) or not holds(self.bus):
                return None
            cmd = self._plan(commands)
            if cmd is None or cmd.reads:
                return None
            rd = self._plan(reads)
            if rd is None or not rd.reads or rd.unique != cmd.unique:
                return None
            a = len(cmd.tx)
            tx, out = self._joined(cmd.tx, rd.tx)
            out[a, REACHED] = 0.0
            h = tx[a]
            h[UNTIL] = until
            h[OPTIONAL] = 0.0 if since is None else 1.0
            h[SINCE] = 0.0 if since is None else since
            h[PERIOD] = period
            got = self._carry(fn, tx, rd, cmd.span + rd.span + self.world.timestep, max(cmd.longest, rd.longest),
                              timeout, True, out)
            if got is None:
                return None
            done = got[1]
            o = out[a]
            reached = o[REACHED] != 0.0
            ran = min(done, a)
            refusal = self._written(cmd, commands, out, ran, None)
            after = float(out[ran - 1, CLOCK_AFTER])
            if not reached:
                self._last, self._done, self._hold = out, ran, -1
                return Stepped(ran, refusal, after, None)
            self._last, self._done, self._hold = out, done + 1, a
            remaining, t0 = float(o[REMAINING]), float(o[CLOCK_AFTER])
            if t0 != after:
                self.sleeps += 1
            values = self._read_values(rd, out[a + 1:], done - a)
            self.steps += 1
            return Stepped(ran, refusal, after, (remaining, t0, values))

    def _joined(self, commands: Any, reads: Any) -> tuple[Any, Any]:
        """The rows of a step (:meth:`step`): ``commands``'s, a :data:`HOLD` row, ``reads``'s; and its output rows
        (buffers per sizes, the hold row's other columns 0)."""
        a, r = len(commands), len(reads)
        got = self._steps_tx.get((a, r))
        if got is None:
            import numpy as np

            got = self._steps_tx[(a, r)] = (np.zeros((a + 1 + r, TX_WIDTH)), np.zeros((a + 1 + r, OUT_WIDTH)))
            got[0][a, OP] = HOLD
        tx = got[0]
        tx[:a] = commands
        tx[a + 1:] = reads
        return got

    @staticmethod
    def _reporting(plan: _Plan) -> Sensor | None:
        """The sensor whose reports the call makes for ``plan`` (:func:`report`), or None (its reads' reports made
        by the firmware's methods after it, as before): a plan with reports of one front (``plan.reports``), whose
        firmware's sensor is a :class:`~joints.sim.sensors.Sensor` reporting (not ideal) from its own stream by its
        compiled stock reads (``_reads``; a generator set as its ``rng``: Python) on its rows (``state``, ``_m``:
        what those reads are given), its and the firmware's methods stock (:data:`_STOCK`, checked before)."""
        if not plan.reports:
            return None
        sensor = plan.unique[0].firmware.sensor
        if type(sensor) is not Sensor or sensor.ideal or sensor.model.ideal or sensor._reads is not sensors.compiled_ops():
            return None
        return sensor

    def values(self, reads: tuple[Any, ...], timeout: float) -> list[int] | None:
        """The values the twins answer to ``reads`` (a tuple of reads, sent one after the other as by :meth:`run`):
        each read's :class:`~joints.codecs.erob_can.ValueReply` value, without the reply (a read is always
        answered by one, from the node it asked: see :meth:`run`). None (nothing sent) where this is not the
        steady case or a request is not a read."""
        with self.world.lock:
            got = self._call(reads, timeout, True)
            if got is None:
                return None
            return self._read_values(*got)

    def run(self, requests: Sequence[Any], timeout: float) -> list[Any] | None:
        """The replies to ``requests`` (to the twins of this bus, sent one after the other by a link whose reply
        timeout is ``timeout``), each once the host has it; a refused request's reply is the last. None (nothing
        sent) where this is not the steady case."""
        with self.world.lock:
            got = self._call(requests, timeout, False)
            if got is None:
                return None
            plan, out, done = got
            if plan.reads:
                return [ec.ValueReply(r.node, v) for r, v in zip(requests, self._read_values(plan, out, done))]
            replies: list[Any] = []
            self._written(plan, requests, out, done, replies)
        return replies

    def acks(self, requests: Sequence[Any], timeout: float) -> tuple[int, Any] | None:
        """:meth:`run` of writes and commands without their replies: (how many were done, the refused start's
        :class:`~joints.codecs.erob_can.ErrorReply` - the last done - or None); :meth:`run` answers each other
        one done ``Ack(request.node)``. None (nothing sent) where this is not the steady case or one is a read."""
        for r in requests:
            if type(r) is ec.Read:
                return None
        with self.world.lock:
            got = self._call(requests, timeout, False)
            if got is None:
                return None
            plan, out, done = got
            return done, self._written(plan, requests, out, done, None)

    def _written(self, plan: _Plan, requests: Sequence[Any], out: Any, done: int, replies: list[Any] | None) -> Any:
        """The fronts and firmware after the call of a plan with writes (``out``'s first ``done`` rows): the
        store and write log, the request counts, a held set-point; each reply into ``replies`` (where given).
        Returns the refused start's error reply (the last done), or None. A write's value is its row's VALUE:
        the request's ``from_wire`` that :meth:`_tx` / :meth:`_refill` put there, an int the firmware's limits
        hold (int32), so exact as a float."""
        tx = plan.tx
        refusal = None
        for k in range(done):
            r, shape, front = requests[k], plan.shapes[k], plan.fronts[k]
            fw = front.firmware
            front.requests += 1
            op = shape.op
            reply: Any = None  # (an Ack)
            if op == TARGET_POSITION:
                fw._keep(((shape.name, int(tx[k, VALUE])),))
            elif op == SETPOINT:
                value = int(tx[k, VALUE])
                fw._keep(((shape.name, value),))
                if out[k, HELD]:
                    front.held = value
                    self.held += 1
                else:
                    target = SETPOINT_OF.get(float(tx[k, MOTION]))
                    if target is not None:
                        fw._keep(((target, value),))
                self.setpoints += 1
            elif op == START:
                if out[k, REFUSED]:
                    reply = refusal = ec.ErrorReply(r.node, sim_can.START_WHILE_OFF)
                else:
                    fw._keep((("start_operating", 1),))
            else:  # a read among writes (run only: acks refuses reads before anything is sent)
                reply = ec.ValueReply(r.node, self._value(fw, shape, out[k, STATUS_AT:].tolist()))
            if replies is not None:
                replies.append(ec.Ack(r.node) if reply is None else reply)
        return refusal

    @property
    def instants(self) -> list[tuple[float, ...]]:
        """Per transaction of the last call (:meth:`run`, :meth:`values`, :meth:`acks`, :meth:`step`): (request
        start, end, reply start, end, the host has it, the world's substeps when the drive acted)."""
        rows = self._last[:self._done].tolist()
        if self._hold >= 0:
            del rows[self._hold]
        return [(o[E0], o[E1], o[R0], o[R1], o[HOST], o[ACTED]) for o in rows]

    def _read_values(self, plan: _Plan, out: Any, done: int) -> list[int]:
        """The values a reads plan's fronts answer (each counts its request), from ``out``'s first ``done`` rows."""
        values: list[int] = []
        value = self._value
        for shape, front, o in zip(plan.shapes, plan.fronts, out[:done, STATUS_AT:].tolist()):  # (those columns)
            front.requests += 1
            values.append(value(front.firmware, shape, o))
        return values

    def _value(self, fw: ErobFirmware, shape: _Shape, o: Sequence[float]) -> int:
        """What the front answers to a read: the firmware's value (the sensors' report of what they saw then),
        saturated, in the protocol's scale, as int32 (``o``: its output row from the status values on)."""
        index, scale, lo, hi, plan, direct = shape.extra
        if direct is not None:  # the status read's finish (see _direct): its sensors report, its value saturated
            fw = plan.fw
            if not self._reported and not fw.sensor.ideal:  # (its stock ``_sensed`` of the row as the read saw it)
                fw._sensed_at(*o[_SENSED:])
            at, lo, hi = direct
            v = int(o[at])
            v = lo if v < lo else hi if hi < v else v  # noqa: FURB136 - (as finish spells it)
        elif plan is not None:  # the status read (its sensors report too, as the firmware's own read)
            v = plan.finish(list(map(int, o[:_SENSED])), self._sensed_row(o))[0]
        else:
            v = int(o[index])
            sensed = _SENSED_READS.get(shape.name)
            if sensed is not None and not self._reported and not fw.sensor.model.ideal:
                v = getattr(fw, sensed)(self._sensed_row(o).__getitem__)
            if v < lo:
                v = lo
            elif v > hi:
                v = hi
        v //= scale
        if v > 0x7FFFFFFF:
            v -= 1 << 32
        return int(v)

    def _sensed_row(self, o: Sequence[float]) -> dict[int, float]:
        """The row's columns the sensors see (column -> value) as they stood at the read, from its output row ``o``:
        one dict kept between reads, its values put in (each read's sensors use it before the next is made)."""
        row = self._row_seen
        row[_TIME], row[_POS], row[_VEL], row[_I_OUT] = o[_SENSED:]
        return row


def prepare(world: Any, bus: Any, host: Any, transport: Any) -> ErobCanExchange | None:
    """The one-call exchange of the eRob twins on ``bus`` (an :class:`ErobCanBus` of ``world``) for the host node
    ``host`` (a :class:`LockstepCanBus` on its medium, wrapped by the link's ``transport``), or None where those
    are not such objects."""
    if type(bus) is not ErobCanBus or type(host) is not LockstepCanBus or host.medium is not bus.medium:
        return None
    if not isinstance(transport, can_transport.PythonCanTransport) or world is None:
        return None
    return ErobCanExchange(world, bus, host, transport)

