"""The reliability harness in CI: a seeded slice of every target with zero violations, and proof that
the harness sees the failures it is there for (each planted bug below is one issue 18 found).

The full run is ``python tests/harness/run.py --count 1000000 --seed S`` (see the README of the
harness in tests/harness/__init__.py); this slice takes a few seconds.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterator

import pytest

from harness import codec_fuzz, endpoint_fuzz, transactions
from harness.report import Report
from harness.run import all_targets, main
from joints.codecs import modbus as mb
from joints.link.base import Link
from joints.sim.modbus_front import ModbusDeviceBus

SEED = 20240618
FRAMES = 3000
CALLS = 1000
MKS_SETUPS = ["mks/mks-serial", "mks/modbus-rtu"]


def violations(report: Report) -> dict[str, dict[str, int]]:
    return {name: dict(t.violations) for name, t in report.targets.items() if t.total_violations}


def test_every_codec_in_both_roles_survives_a_fuzzed_slice() -> None:
    report = Report(SEED)
    codec_fuzz.run(report, list(codec_fuzz.targets()), FRAMES, SEED)
    assert violations(report) == {}, "\n".join(report.lines())
    assert len(report.targets) == len(codec_fuzz.targets()) >= 9
    for t in report.targets.values():
        assert t.units >= FRAMES
        assert t.checks["exception"] >= FRAMES and t.checks["hang"] > 0
        assert t.checks["reencode"] + t.checks["reply-shape"] + t.checks["step-type"] > 0


def test_every_twin_endpoint_of_the_registry_survives_a_fuzzed_slice() -> None:
    names = [n for n, _f, _p in endpoint_fuzz.endpoints()]
    assert {"erob/modbus-rtu", "zlac8015d/modbus-rtu", "erob/erob-can", "erob/canopen", "mks/mks-serial",
            "mks/modbus-rtu"} <= set(names)
    report = Report(SEED)
    endpoint_fuzz.run(report, names, FRAMES, SEED)
    assert violations(report) == {}, "\n".join(report.lines())
    for name, t in report.targets.items():
        assert t.units >= FRAMES
        assert t.checks["unanswered"] > 100 and t.checks["reply-to-other-address"] > 100, name
    assert not report.uncovered  # every protocol of the registry has a fuzz adapter
    modbus = report.targets["endpoint erob/modbus-rtu"]
    assert modbus.checks["reply-to-broadcast"] > 100 and modbus.checks["ack-without-write"] > 10
    mks = report.targets["endpoint mks/modbus-rtu"]  # V1.0.6+ failure replies: judged as "not executed"
    assert mks.checks["failed-but-written"] > 10 and mks.checks["ack-without-write"] > 10


def test_transactions_under_ten_percent_faults_keep_every_invariant() -> None:
    report = Report(SEED)
    transactions.run(report, list(transactions.SETUPS), CALLS, SEED)
    transactions.run(report, list(transactions.SETUPS), CALLS // 2, SEED, echo=True)
    assert violations(report) == {}, "\n".join(report.lines())
    for name, t in report.targets.items():
        assert t.units >= CALLS // 2, name
        assert t.checks["wrong-value"] > CALLS // 4 and t.checks["write-lost-but-ok"] > CALLS // 10, name
        assert t.checks["write-not-outcome-unknown"] > 0, name  # the line did lose answers to writes
        assert t.checks["executed-twice"] > 0, name


@pytest.mark.mks_firmware("v1.0.5", "v1.0.6")  # v1.0.9, the default, is in the two slices above
def test_the_mks_slice_keeps_every_invariant_on_the_older_firmware_profiles(mks_firmware: str) -> None:
    report = Report(SEED)
    endpoint_fuzz.run(report, MKS_SETUPS, FRAMES, SEED)
    transactions.run(report, MKS_SETUPS, CALLS, SEED)
    assert violations(report) == {}, "\n".join(report.lines())
    assert all(t.units >= FRAMES if n.startswith("endpoint") else t.units >= CALLS // 2 for n, t in report.targets.items())
    assert len(report.targets) == 4
    failed = report.targets["endpoint mks/modbus-rtu"].checks["failed-but-written"]
    assert (failed > 10) == (mks_firmware != "v1.0.5")  # the failure replies came with V1.0.6


def test_the_command_runs_and_exits_zero(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["--count", "300", "--transactions", "200", "--seed", "1", "--target", "codec:modbus*",
                 "--target", "endpoint:zlac*", "--target", "transactions:erob/modbus-rtu"]) == 0
    out = capsys.readouterr().out
    assert "TOTAL VIOLATIONS: 0" in out and "codec modbus-rtu/device" in out
    assert "endpoint zlac8015d/modbus-rtu" in out and "transactions erob/modbus-rtu" in out
    assert main(["--list"]) == 0 and capsys.readouterr().out.split() == all_targets()


# --- the harness has teeth: planted bugs are found ---------------------------------------------------


@pytest.fixture
def undo(monkeypatch: pytest.MonkeyPatch) -> Iterator[pytest.MonkeyPatch]:
    yield monkeypatch


def test_it_sees_a_twin_that_answers_broadcasts(undo: pytest.MonkeyPatch) -> None:
    exchange = ModbusDeviceBus.exchange

    def answers_everything(self: ModbusDeviceBus, msg: mb.Request | mb.UnsupportedRequest) -> mb.Reply | None:
        if msg.slave == 0 and self.slaves:
            return next(iter(self.slaves.values())).handle(msg)
        return exchange(self, msg)

    undo.setattr(ModbusDeviceBus, "exchange", answers_everything)
    report = Report(SEED)
    endpoint_fuzz.run(report, ["erob/modbus-rtu"], 1000, SEED)
    assert report.targets["endpoint erob/modbus-rtu"].violations["reply-to-broadcast"] > 0


def test_it_sees_a_silence_that_does_not_resynchronise(undo: pytest.MonkeyPatch) -> None:
    """The bug issue 18 found: ``feed(b"")`` after ``flush()`` cleared the silence again."""
    feed = mb.ModbusRtuCodec.feed

    def old_feed(self: mb.ModbusRtuCodec, data: bytes | bytearray) -> None:
        feed(self, data)
        self._silent = False  # the old behaviour, planted

    def old_silence(self: ModbusDeviceBus) -> bytes:
        self._codec.flush()
        return self.receive(b"")

    undo.setattr(mb.ModbusRtuCodec, "feed", old_feed)
    undo.setattr(ModbusDeviceBus, "silence", old_silence)
    report = Report(SEED)
    endpoint_fuzz.run(report, ["erob/modbus-rtu"], 3000, SEED)
    t = report.targets["endpoint erob/modbus-rtu"]
    assert t.violations["executed-invalid"] + t.violations["unanswered"] > 0


def test_it_sees_a_link_that_takes_late_replies(undo: pytest.MonkeyPatch) -> None:
    undo.setattr(Link, "_discard_late", lambda self: self.framing.discard())  # no late window
    report = Report(SEED)
    transactions.run(report, ["erob/modbus-rtu"], 2000, SEED)
    t = report.targets["transactions erob/modbus-rtu (in process)"]
    assert t.violations["wrong-value"] + t.violations["late-reply-accepted"] > 0


def test_it_sees_a_timed_out_write_reported_as_a_plain_failure(undo: pytest.MonkeyPatch) -> None:
    from joints.link.modbus import ModbusRule

    undo.setattr(ModbusRule, "is_write", lambda self, request: False)
    report = Report(SEED)
    transactions.run(report, ["zlac8015d/modbus-rtu"], 1000, SEED)
    assert report.targets["transactions zlac8015d/modbus-rtu (in process)"].violations[
        "write-not-outcome-unknown"] > 0


# --- reads serve changing values (issue 28: the MKS status reads served one value each) ------------------

@pytest.mark.mks_firmware
@pytest.mark.parametrize("name", MKS_SETUPS)
def test_every_read_parameter_serves_a_new_value_after_every_read(name: str, undo: pytest.MonkeyPatch) -> None:
    truths: list[transactions.Truth] = []
    install = transactions.Truth.install

    def keep(self: transactions.Truth, fw: object) -> None:
        truths.append(self)
        install(self, fw)

    undo.setattr(transactions.Truth, "install", keep)
    report = Report(SEED)
    transactions.run(report, [name], 300, SEED)
    assert violations(report) == {}, "\n".join(report.lines())
    served = Counter(n for n, _v in truths[0].served)
    reads = transactions.SETUPS[name].read_names
    assert set(served) >= set(reads) and all(served[n] > 50 for n in reads), served  # distinct values per name


@pytest.mark.mks_firmware
@pytest.mark.parametrize("name", MKS_SETUPS)
def test_it_sees_a_read_answered_by_the_previous_reply(name: str, undo: pytest.MonkeyPatch) -> None:
    request = Link.request
    last: dict[str, object] = {}

    def stale(self: Link[object], req: object, *, idempotent: bool = False) -> object:
        reply = request(self, req, idempotent=idempotent)
        if not self.rule.is_read(req):
            return reply
        before = last.get(repr(req), reply)
        last[repr(req)] = reply
        return before

    undo.setattr(Link, "request", stale)
    report = Report(SEED)
    transactions.run(report, [name], 300, SEED)
    assert report.targets[f"transactions {name} (in process)"].violations["late-reply-accepted"] > 0


class _Misplaced:
    """A driver whose block reads put each value under the next parameter's name."""

    def __init__(self, access: object) -> None:
        self._access = access

    def __getattr__(self, name: str) -> object:
        return getattr(self._access, name)

    def read_many(self, names: list[str]) -> dict[str, int]:
        got: dict[str, int] = self._access.read_many(names)  # type: ignore[attr-defined]
        values = list(got.values())
        return dict(zip(got, values[1:] + values[:1]))


@pytest.mark.mks_firmware
@pytest.mark.parametrize("name", MKS_SETUPS)
def test_it_sees_a_value_read_into_the_wrong_parameter(name: str, undo: pytest.MonkeyPatch) -> None:
    make = transactions.in_process

    def misplaced(*args: object, **kwargs: object) -> transactions.Bench:
        bench = make(*args, **kwargs)  # type: ignore[arg-type]
        bench.access = _Misplaced(bench.access)
        return bench

    undo.setattr(transactions, "in_process", misplaced)
    report = Report(SEED)
    transactions.run(report, [name], 300, SEED)
    assert report.targets[f"transactions {name} (in process)"].violations["wrong-value"] > 0
