"""Coverage-guided fuzzing of one codec or endpoint with atheris (optional: ``pip install atheris``).

``python tests/harness/run.py --atheris codec:modbus-rtu/device --count 1000000``. The fuzzer's
input is turned into what the plain loop feeds (a byte stream with cut and silence points, or a
list of CAN frames) and judged by the same invariants; a violation raises AssertionError, which
atheris reports with the input that caused it.
"""

from __future__ import annotations

import random
import sys
from collections.abc import Callable
from typing import Any

from harness import codec_fuzz, corpus, endpoint_fuzz
from harness.report import Target
from joints.errors import JointsError


def _frames(data: bytes) -> list[Any]:
    """CAN frames from fuzz bytes: id (2 bytes, 11 bits), flags, then as many data bytes as flags say."""
    out, i = [], 0
    while i + 3 <= len(data):
        can_id = int.from_bytes(data[i:i + 2], "big") & 0x7FF
        flags = data[i + 2]
        n = flags & 0x0F
        payload = data[i + 3:i + 3 + min(n, 8)]
        out.append(corpus.can_frame(can_id, payload, remote=bool(flags & 0x80), extended=bool(flags & 0x40)))
        i += 3 + len(payload)
    return out


def _chunks(data: bytes) -> list[tuple[bytes, bool]]:
    """Byte chunks from fuzz bytes: a length byte (top bit: silence after), then that many bytes."""
    out, i = [], 0
    while i < len(data):
        head = data[i]
        n = (head & 0x3F) or 1
        out.append((data[i + 1:i + 1 + n], bool(head & 0x80)))
        i += 1 + n
    return out


def one_input(name: str) -> Callable[[bytes], None]:
    kind, rest = name.split(":", 1)
    t = Target(name, kind)
    if kind == "codec":
        codec = codec_fuzz.targets()[rest]()

        def codec_input(data: bytes) -> None:
            before = t.total_violations
            rng = random.Random(data[:4])
            if isinstance(codec, codec_fuzz.StreamCodec):
                codec.case(t, rng, data)
            else:
                for f in _frames(data):
                    try:
                        result: Any = codec.step(f)
                    except Exception as exc:  # noqa: BLE001 - judged below
                        result = exc
                    if isinstance(result, Exception) and not isinstance(result, JointsError):
                        raise AssertionError(f"{name}: {result!r}") from result  # noqa: TRY004 - a finding
                    codec.check(t, f, result)
            if t.total_violations > before:
                raise AssertionError(f"{name}: {dict(t.violations)} {t.examples}")

        return codec_input
    known = {n: (f, p) for n, f, p in endpoint_fuzz.endpoints()}
    family, protocol = known[rest]
    make = endpoint_fuzz.ADAPTERS.get(protocol, endpoint_fuzz.GenericAdapter)
    adapter = make(endpoint_fuzz.build(family, protocol), random.Random(0))

    def endpoint_input(data: bytes) -> None:
        before = t.total_violations
        if isinstance(adapter, endpoint_fuzz.ModbusAdapter):
            adapter.run_chunks(t, _chunks(data))
        elif isinstance(adapter, endpoint_fuzz.ErobCanAdapter):
            adapter.run_frames(t, _frames(data))
        else:
            adapter.case(t)
        if t.total_violations > before:
            raise AssertionError(f"{name}: {dict(t.violations)} {t.examples}")

    return endpoint_input


def main(name: str, runs: int, seed: int) -> int:
    try:
        import atheris
    except ImportError:
        print("atheris is not installed (pip install atheris); the plain loop covers the same targets", file=sys.stderr)
        return 2
    test = one_input(name)
    atheris.instrument_all()
    atheris.Setup([sys.argv[0], f"-runs={runs}", f"-seed={seed or 1}"], test)
    atheris.Fuzz()
    return 0
