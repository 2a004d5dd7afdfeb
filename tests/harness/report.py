"""Counts of a harness run: per target, units exercised and, per invariant, checks and violations."""

from __future__ import annotations

import time
from collections import Counter
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field

EXAMPLES = 5  #: violations kept per invariant and target, with what reproduces them


@dataclass
class Target:
    """One fuzzed codec, one twin endpoint, or one transaction setup."""

    name: str
    kind: str  #: "codec", "endpoint" or "transactions"
    unit: str = "frames"  #: what :attr:`units` counts
    units: int = 0
    seconds: float = 0.0
    checks: Counter[str] = field(default_factory=Counter)
    violations: Counter[str] = field(default_factory=Counter)
    examples: dict[str, list[str]] = field(default_factory=dict)
    notes: Counter[str] = field(default_factory=Counter)  #: outcomes worth reporting (not invariants)

    def check(self, invariant: str, ok: bool) -> bool:
        """Count one check of ``invariant``; a violation if not ``ok`` (add what happened with :meth:`example`)."""
        self.checks[invariant] += 1
        if not ok:
            self.violations[invariant] += 1
        return ok

    def example(self, invariant: str, detail: str) -> None:
        """What a violation of ``invariant`` looked like (the first few are kept)."""
        kept = self.examples.setdefault(invariant, [])
        if len(kept) < EXAMPLES:
            kept.append(detail)

    def passed(self, invariant: str, n: int = 1) -> None:
        """``n`` checks of ``invariant`` that held (bulk counting in hot loops)."""
        self.checks[invariant] += n

    def violate(self, invariant: str, detail: str) -> None:
        self.checks[invariant] += 0
        self.violations[invariant] += 1
        kept = self.examples.setdefault(invariant, [])
        if len(kept) < EXAMPLES:
            kept.append(detail)

    @property
    def total_violations(self) -> int:
        return sum(self.violations.values())


class Report:
    """Every target of one run, printed as a table; ``ok`` is False on any violation."""

    def __init__(self, seed: int) -> None:
        self.seed = seed
        self.targets: dict[str, Target] = {}
        self.uncovered: list[str] = []  #: endpoints or protocols without a fuzz adapter (generic checks only)
        self.started = time.monotonic()

    def target(self, name: str, kind: str, unit: str = "frames") -> Target:
        t = self.targets.get(name)
        if t is None:
            t = self.targets[name] = Target(name, kind, unit)
        return t

    @contextmanager
    def timed(self, target: Target) -> Iterator[Target]:
        t0 = time.monotonic()
        try:
            yield target
        finally:
            target.seconds += time.monotonic() - t0

    @property
    def violations(self) -> int:
        return sum(t.total_violations for t in self.targets.values())

    @property
    def ok(self) -> bool:
        return self.violations == 0

    def lines(self) -> list[str]:
        out = [f"harness seed {self.seed}: {len(self.targets)} targets, {time.monotonic() - self.started:.1f} s wall"]
        for kind, title in (("codec", "codecs"), ("endpoint", "twin endpoints"), ("transactions", "transactions")):
            targets = [t for t in self.targets.values() if t.kind == kind]
            if not targets:
                continue
            out.append("")
            out.append(f"{title}:")
            for t in targets:
                rate = t.units / t.seconds if t.seconds > 0 else 0.0
                out.append(f"  {t.name:<34} {t.units:>10,} {t.unit:<12} {t.seconds:8.1f} s  ({rate:,.0f}/s)"
                           f"  violations {t.total_violations}")
                for inv in sorted(t.checks):
                    out.append(f"      {inv:<32} checked {t.checks[inv]:>12,}   violations {t.violations[inv]}")
                    for ex in t.examples.get(inv, []):
                        out.append(f"          e.g. {ex}")
                if t.notes:
                    out.append("      outcomes: " + ", ".join(f"{k} {v:,}" for k, v in sorted(t.notes.items())))
        for u in self.uncovered:
            out.append(f"note: {u}")
        out.append("")
        totals: Counter[str] = Counter()
        for t in self.targets.values():
            totals.update(t.violations)
            for inv in t.checks:
                totals[inv] += 0
        out.append("violations per invariant: " + ", ".join(f"{k} {v}" for k, v in sorted(totals.items())))
        out.append(f"TOTAL VIOLATIONS: {self.violations}")
        return out

    def print(self) -> None:
        print("\n".join(self.lines()), flush=True)
