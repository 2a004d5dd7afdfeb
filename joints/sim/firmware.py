"""A drive's firmware without a protocol: its parameters by name, and hooks where behaviour goes.

Rule: no protocol here. A twin is its drive's firmware (behaviour, by parameter name) plus thin
protocol fronts (frames in, firmware calls, frames out: :mod:`joints.sim.modbus_front`; eRob CAN
custom, CANopen and MKS native next), and one firmware may stand behind several fronts. A
:class:`Firmware` holds one typed integer per parameter of a
:class:`~joints.devices.params.ParamSet` (power-on defaults, then saved settings); every front
reaches it through the same calls, by parameter NAME:

* :meth:`Firmware.read_many` / :meth:`Firmware.read` - status parameters are computed when they
  are read (:attr:`Firmware.computed`), never published per substep;
* :meth:`Firmware.write_many` / :meth:`Firmware.write` - atomic: every value is validated
  (known, writable, in range, allowed in this state) before any is stored or acted on, so a
  refused block has no effect at all;
* :meth:`Firmware.frame_received` - a frame addressed to this drive arrived (the communication
  watchdog's food);
* :meth:`Firmware.power_cycle` - power off/on: saved settings survive, everything else returns
  to its power-on value; :attr:`Firmware.power_on_values` keeps what was in force at power-on
  (a node id or baud rate written later takes effect only after the next power cycle).

Command-to-motion delay (:attr:`Firmware.command_delay`, s; 0 by default): a drive acts on a
motion command some time after the frame carrying it arrived. A write that names one of the
firmware's :attr:`Firmware.DELAYED` parameters is validated at once (a refusal is answered at
once) but stored and acted on only :attr:`Firmware.command_delay` seconds later, when the world
calls :meth:`Firmware.tick` at or after that time; every write arriving while one is pending
queues behind it, so the drive acts on writes in their order. A read of a parameter whose write
is still pending returns its old value. Settings writes and reads are never delayed.

Refusals are :class:`~joints.errors.ParameterRefused` with a protocol-neutral
:class:`~joints.errors.Refusal`; the front maps the reason to its protocol's answer.

A plain ``Firmware(params)`` is a bare parameter store (a scripted drive in tests); twins
subclass it and override :meth:`Firmware.check_write` (refuse in this state),
:meth:`Firmware.on_write` (act on commands and settings), :meth:`Firmware.on_read` (before a read
is served) and fill :attr:`Firmware.computed`.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence

from joints.devices.params import ParamSet
from joints.errors import CommandError, ParameterRefused, Refusal

__all__ = ["WRITE_LOG_LIMIT", "Firmware"]

#: accepted writes kept in :attr:`Firmware.write_log` (the oldest half is dropped beyond this)
WRITE_LOG_LIMIT = 100_000


class Firmware:
    """The parameter store of one drive, by name; subclasses add the drive's behaviour."""

    #: parameters whose writes take effect :attr:`command_delay` after they arrive (motion commands)
    DELAYED: frozenset[str] = frozenset()

    def __init__(self, params: ParamSet, *, values: Mapping[str, int] | None = None) -> None:
        self.params = params
        #: per name: (writable, lowest, highest) accepted by a write
        self._limits: dict[str, tuple[bool, int, int]] = {}
        #: per name: the type's range (device-internal sets saturate to it)
        self._type_range: dict[str, tuple[int, int]] = {}
        self._readable = frozenset(p.name for p in params if p.access.readable)
        for p in params:
            lo, hi = p.type_range
            self._type_range[p.name] = (lo, hi)
            self._limits[p.name] = (p.access.writable, lo if p.minimum is None else max(lo, p.minimum),
                                    hi if p.maximum is None else min(hi, p.maximum))
        #: power-on value of every parameter (the manual's defaults, then ``values``)
        self.defaults: dict[str, int] = {p.name: p.default for p in params}
        for name, value in (values or {}).items():
            self.params.get(name)  # an unknown name is a RegisterError
            self.defaults[name] = self._saturate(name, value)
        #: settings kept over a power cycle (what "save parameters" stored)
        self.saved: dict[str, int] = {}
        #: the stored value of every parameter
        self.values: dict[str, int] = dict(self.defaults)
        #: the values in force since the last power-on
        self.power_on_values: Mapping[str, int] = dict(self.values)
        #: status parameters computed when read: name -> function returning the value now
        self.computed: dict[str, Callable[[], int]] = {}
        #: every accepted write as (name, value), in order (tests, traces)
        self.write_log: list[tuple[str, int]] = []
        #: s between a motion command's arrival and the drive acting on it (see the module docstring)
        self.command_delay = 0.0
        #: accepted writes waiting for their time: (due [s], [(name, value)]), oldest first
        self.pending: list[tuple[float, list[tuple[str, int]]]] = []

    # -- the drive's own access (no access rules) --------------------------------------------
    def _saturate(self, name: str, value: int) -> int:
        lo, hi = self._type_range[name]
        # saturate like a drive's status values would, never wrap silently
        return min(max(int(value), lo), hi)

    def get(self, name: str) -> int:
        """The value of a parameter now (computed ones are computed)."""
        fn = self.computed.get(name)
        if fn is not None:
            return self._saturate(name, fn())
        try:
            return self.values[name]
        except KeyError:
            raise ParameterRefused(Refusal.UNKNOWN, name, self.params.device) from None

    def set(self, name: str, value: int) -> None:
        """Store a value (the device itself: no access check, saturated to the type's range)."""
        if name not in self._type_range:
            raise ParameterRefused(Refusal.UNKNOWN, name, self.params.device)
        self.values[name] = self._saturate(name, value)

    # -- what fronts call ----------------------------------------------------------------------
    def read(self, name: str) -> int:
        """Read one parameter as a protocol would (refused if unknown or write-only)."""
        return self.read_many((name,))[0]

    def read_many(self, names: Sequence[str]) -> list[int]:
        """Read several parameters as one request (one :meth:`on_read`, one moment in time)."""
        return self.reader(names)()

    def reader(self, names: Sequence[str]) -> Callable[[], list[int]]:
        """A prepared read of ``names`` (validated once; a front keeps one per block it serves).

        Calling it is :meth:`read_many` without the checks. Which parameters are computed is
        looked up here, so :attr:`computed` must be complete before readers are made (fill it in
        ``__init__``).
        """
        names = tuple(names)
        readable = self._readable
        for name in names:
            if name not in readable:
                reason = Refusal.NOT_READABLE if name in self._limits else Refusal.UNKNOWN
                raise ParameterRefused(reason, name, self.params.device)
        entries = tuple((name, self.computed.get(name), *self._type_range[name]) for name in names)

        def read() -> list[int]:
            self.on_read(names)
            values = self.values
            out: list[int] = []
            for name, fn, lo, hi in entries:
                if fn is None:
                    out.append(values[name])
                    continue
                v = fn()
                if v < lo:  # saturate, never wrap
                    v = lo
                elif v > hi:
                    v = hi
                out.append(v)
            return out

        return read

    def write(self, name: str, value: int) -> None:
        """Write one parameter as a protocol would (see :meth:`write_many`)."""
        self.write_many(((name, value),))

    def write_many(self, items: Sequence[tuple[str, int]]) -> None:
        """Write several parameters atomically: all are validated before any takes effect.

        Raises :class:`~joints.errors.ParameterRefused` (and changes nothing) if a name is
        unknown or not writable, a value outside its type or documented range, or the drive
        refuses it in its present state (:meth:`check_write`). Then every value is stored, logged
        and acted on (:meth:`on_write`), in order.
        """
        limits = self._limits
        checked: list[tuple[str, int]] = []
        for name, value in items:
            lim = limits.get(name)
            if lim is None:
                raise ParameterRefused(Refusal.UNKNOWN, name, self.params.device)
            writable, lo, hi = lim
            if not writable:
                raise ParameterRefused(Refusal.NOT_WRITABLE, name)
            if type(value) is not int or not lo <= value <= hi:
                try:
                    value = self.params.get(name).check(value)
                except CommandError as exc:
                    raise ParameterRefused(Refusal.OUT_OF_RANGE, name, str(exc)) from exc
            self.check_write(name, value)
            checked.append((name, value))
        if self.pending or (self.command_delay > 0 and any(name in self.DELAYED for name, _ in checked)):
            self.pending.append((float(getattr(self, "time", 0.0)) + self.command_delay, checked))
            return
        self._store(checked)

    def tick(self, t: float) -> None:
        """Simulated time reached ``t``: act on the pending writes that are due (see :attr:`command_delay`)."""
        pending = self.pending
        while pending and pending[0][0] <= t + 1e-9:
            self._store(pending.pop(0)[1])

    def _store(self, checked: list[tuple[str, int]]) -> None:
        """Store, log and act on validated writes."""
        self._keep(checked)
        for name, value in checked:
            self.on_write(name, value)

    def _keep(self, checked: Sequence[tuple[str, int]]) -> None:
        """The parameter store's part of :meth:`_store`: the values stored, the writes logged (the log trimmed)."""
        values = self.values
        for name, value in checked:
            values[name] = value
        log = self.write_log
        log.extend(checked)
        if len(log) > WRITE_LOG_LIMIT:
            del log[: WRITE_LOG_LIMIT // 2]

    def frame_received(self) -> None:
        """A frame addressed to this drive (or broadcast) arrived, before it is served."""

    def power_cycle(self) -> None:
        """Power off/on: saved settings survive, every other parameter returns to its default."""
        self.pending.clear()  # writes the drive had not acted on yet are lost with the power
        values = self.values  # updated in place: subclasses may hold a reference
        values.update(self.defaults)
        values.update(self.saved)
        self.power_on_values = dict(values)
        self.write_log.clear()

    def save(self, names: Sequence[str]) -> None:
        """Keep the present values of ``names`` over power cycles ("save parameters")."""
        values = self.values
        self.saved = {n: values[n] for n in names}

    # -- hooks for the drive's behaviour -------------------------------------------------------
    def on_read(self, names: Sequence[str]) -> None:
        """Called once per read request before its values are taken."""

    def check_write(self, name: str, value: int) -> None:
        """Raise :class:`~joints.errors.ParameterRefused` to refuse a valid value in this state."""

    def on_write(self, name: str, value: int) -> None:
        """Called after an accepted write was stored (act on commands and settings here)."""

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.params.device!r})"
