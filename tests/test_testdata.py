"""The vendored test data is whole, and the same as ../shared where that folder exists."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent / "data"))
import refresh

MANIFEST = json.loads(refresh.MANIFEST.read_text(encoding="utf-8"))


def test_manifest_lists_every_vendored_file() -> None:
    assert set(MANIFEST) == set(refresh.FILES)


@pytest.mark.parametrize("name", sorted(refresh.FILES))
def test_vendored_file_matches_manifest_and_shared(name: str) -> None:
    path = refresh.HERE / name
    assert path.is_file(), f"{name} is missing from tests/data; run python tests/data/refresh.py"
    assert refresh.sha256(path) == MANIFEST[name]["sha256"], f"{name} changed without refresh.py"
    shared = refresh.default_shared() / refresh.FILES[name]
    if shared.is_file():  # beside a checkout with ../shared: the copy must be current
        assert refresh.sha256(shared) == MANIFEST[name]["sha256"], (
            f"{name} differs from {refresh.FILES[name]} in ../shared; run python tests/data/refresh.py")


def test_no_test_reads_outside_the_repository() -> None:
    tests = Path(__file__).resolve().parent
    offenders = [str(p.relative_to(tests)) for p in tests.rglob("*.py")
                 if p.name != "test_testdata.py" and p.parent.name != "data"
                 and '"shared"' in p.read_text(encoding="utf-8")]
    assert not offenders, f"tests that read ../shared directly: {offenders}"
