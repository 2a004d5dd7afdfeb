"""The README and docs/: every `joints` command shown exists with the options shown, every relative link
resolves (anchors included), and no page names a path of one machine."""

from __future__ import annotations

import argparse
import re
import shlex
from pathlib import Path

import pytest

from joints.cli import build_parser

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
#: where a path would be one machine's (a user's home, a checkout, a shared mount)
#: (the roots are spelled as names, so this file names no machine path itself)
_ROOTS = ("work", "home", "Users", "root", "opt", "mnt")
MACHINE_PATHS = re.compile(r"(?<![\w.])(" + "|".join(f"/{r}/" for r in _ROOTS) + r"|[A-Z]:\\\\)|\.\./shared")


def commands(text: str) -> list[str]:
    """`joints ...` lines of code blocks and inline code spans (comments cut)."""
    found: list[str] = []
    block = False
    for line in text.splitlines():
        if line.startswith("```"):
            block = not block
        elif block and line.startswith("joints "):
            found.append(line)
        elif not block:
            found += re.findall(r"`(joints [^`]+)`", line)
    return [c.split("#")[0].strip() for c in found]


def _sub(p: argparse.ArgumentParser, name: str) -> argparse.ArgumentParser | None:
    for a in p._actions:
        if isinstance(a, argparse._SubParsersAction) and name in a.choices:
            sub: argparse.ArgumentParser = a.choices[name]
            return sub
    return None


def problems(cmd: str, parser: argparse.ArgumentParser) -> list[str]:
    """What is wrong with one shown command: an unknown (sub)command or an option it does not take."""
    try:
        words = shlex.split(cmd)
    except ValueError:
        words = cmd.split()
    p, path, i = parser, [], 1
    while i < len(words) and not words[i].startswith("-"):
        sub = _sub(p, words[i])
        if sub is None:
            break
        p, i = sub, i + 1
        path.append(words[i - 1])
    if not path:
        return [f"no command {words[1]!r}" if len(words) > 1 else "no command"]
    options = {o for a in p._actions for o in a.option_strings}
    return [f"`joints {' '.join(path)}` has no option {w.split('=')[0]}" for w in words[i:]
            if w.startswith("--") and w.split("=")[0] not in options]


def test_the_pages_exist() -> None:
    names = {p.relative_to(ROOT).as_posix() for p in PAGES}
    assert {"README.md", "docs/architecture.md", "docs/configuration.md", "docs/cli.md"} <= names


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.relative_to(ROOT).as_posix())
def test_every_command_shown_exists(page: Path) -> None:
    parser = build_parser()
    bad = [f"{c}: {m}" for c in commands(page.read_text(encoding="utf-8")) for m in problems(c, parser)]
    assert not bad, "\n".join(bad)


def test_the_command_check_finds_what_does_not_exist() -> None:
    parser = build_parser()
    text = "```\njoints scan --bogus\njoints frobnicate x\n```\nand `joints params dump a b -o x --nope`\n"
    shown = commands(text)
    assert [problems(c, parser) for c in shown] == [
        ["`joints scan` has no option --bogus"], ["no command 'frobnicate'"],
        ["`joints params dump` has no option --nope"]]
    assert problems("joints sim serve robot.toml --hardware-config t.toml", parser) == []


def _slug(heading: str) -> str:
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.relative_to(ROOT).as_posix())
def test_links_resolve(page: Path) -> None:
    bad: list[str] = []
    for target in re.findall(r"\]\(([^)\s]+)\)", page.read_text(encoding="utf-8")):
        if re.match(r"[a-z]+:", target):
            continue
        path, _, anchor = target.partition("#")
        dest = (page.parent / path).resolve() if path else page
        if not dest.exists():
            bad.append(f"{target}: no such file")
        elif anchor and dest.suffix == ".md":
            headings = re.findall(r"^#+ (.*)$", dest.read_text(encoding="utf-8"), re.MULTILINE)
            if anchor not in {_slug(h) for h in headings}:
                bad.append(f"{target}: no such heading")
    assert not bad, "\n".join(bad)


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.relative_to(ROOT).as_posix())
def test_no_machine_paths(page: Path) -> None:
    lines = [f"{n}: {line}" for n, line in enumerate(page.read_text(encoding="utf-8").splitlines(), 1)
             if MACHINE_PATHS.search(line)]
    assert not lines, "\n".join(lines)


def test_the_path_check_sees_machine_paths() -> None:
    home = "/".join(("", "home", "someone", "manuals"))  # noqa: FLY002 - this file spells no machine path
    assert MACHINE_PATHS.search(f"see {home}") and MACHINE_PATHS.search("../shared/vectors/ERRATA.md")
    assert not MACHINE_PATHS.search("port = /dev/ttyUSB0, --bind rs485=/tmp/ttyJOINTS0")
