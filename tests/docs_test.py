"""The repository explains itself: no tracked file points at the project's private planning
notes, and every relative link in README.md and docs/*.md reaches a file in the repository.

Needs only git and the checkout; it imports nothing from heliquad.
"""

from __future__ import annotations

import pathlib
import re
import shutil
import subprocess

import pytest

ROOT = pathlib.Path(__file__).resolve().parent.parent

#: The private notes that live beside the repository and ship with no copy of it. Users have
#: none of them, so nothing tracked may send a reader there. What the repository needs from
#: them is in docs/paper.md (the paper), docs/architecture.md, docs/teensy35.md and
#: docs/teensy35-emulator.md. Written as regular expressions, so this file does not match.
PRIVATE_NOTES = re.compile(r"SPEC\.md|DESIGN\.md|TEENSY35\.md|\.\./shared")

#: Link targets with a scheme (https:, mailto:, ...) are not files in the repository.
SCHEME = re.compile(r"^[A-Za-z][A-Za-z0-9+.-]*:")
#: Inline links and images, [text](target) and ![alt](target); the target may be <...> and
#: may carry a title.
INLINE_LINK = re.compile(r"!?\[[^\]]*\]\(\s*(<[^>]*>|[^)\s]+)(?:\s+[\"'(][^)]*)?\s*\)")
#: Reference definitions, [label]: target.
REFERENCE_LINK = re.compile(r"^\s{0,3}\[[^\]]+\]:\s*(<[^>]*>|\S+)", re.MULTILINE)
FENCE = re.compile(r"^\s*(```|~~~).*?^\s*\1", re.MULTILINE | re.DOTALL)
CODE_SPAN = re.compile(r"(`+)(?:(?!\1).)+?\1", re.DOTALL)


def _tracked_files():
    if shutil.which("git") is None:
        pytest.skip("git is not installed")
    run = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True)
    if run.returncode != 0:
        pytest.skip("not a git checkout: " + run.stderr.decode(errors="replace").strip())
    names = [n for n in run.stdout.decode().split("\0") if n]
    return [ROOT / n for n in names if (ROOT / n).is_file()]


def _text(path):
    """The file's text, or None for a binary file (a NUL byte in it)."""
    data = path.read_bytes()
    if b"\0" in data:
        return None
    return data.decode("utf-8", errors="replace")


def test_no_tracked_file_points_at_the_private_notes():
    offenders = []
    for path in _tracked_files():
        text = _text(path)
        if text is None:
            continue
        for number, line in enumerate(text.splitlines(), 1):
            if PRIVATE_NOTES.search(line):
                offenders.append(f"{path.relative_to(ROOT)}:{number}: {line.strip()}")
    assert not offenders, ("these lines cite notes that users do not have; point at "
                           "docs/paper.md or the docs instead:\n" + "\n".join(offenders))


def _markdown_pages():
    return [ROOT / "README.md"] + sorted((ROOT / "docs").glob("*.md"))


def _link_targets(text):
    """Every link target of a Markdown page, code blocks and code spans left out."""
    text = CODE_SPAN.sub("", FENCE.sub("", text))
    for match in list(INLINE_LINK.finditer(text)) + list(REFERENCE_LINK.finditer(text)):
        yield match.group(1).strip("<>")


def test_the_link_finder_sees_what_it_should():
    page = ("See [paper](docs/paper.md#step-2) and ![plot](img/a.png \"title\").\n"
            "[ref]: <docs/method.md>\n"
            "`[not](a-link.md)`\n"
            "```\n[nor](this.md)\n```\n")
    assert list(_link_targets(page)) == ["docs/paper.md#step-2", "img/a.png", "docs/method.md"]


@pytest.mark.parametrize("page", _markdown_pages(), ids=lambda p: str(p.relative_to(ROOT)))
def test_every_relative_link_reaches_a_file_in_the_repository(page):
    broken = []
    for target in _link_targets(page.read_text(encoding="utf-8")):
        if SCHEME.match(target) or target.startswith("#"):
            continue
        path_part = re.split(r"[#?]", target, maxsplit=1)[0]
        resolved = (page.parent / path_part).resolve()
        if not resolved.is_relative_to(ROOT):
            broken.append(f"{target} (outside the repository)")
        elif not resolved.exists():
            broken.append(f"{target} (no such file)")
    assert not broken, f"{page.relative_to(ROOT)}: broken links: " + ", ".join(broken)


#: A path in a code span: a top-level folder of the repository, then a path (``*`` allowed).
REPO_PATH = re.compile(r"^(?:host|sim|firmware|tests|benchmarks|docs|\.ci)/[\w./*-]*$")
#: A file name in a code span of a room's paragraph: ``name.py``, ``name.*``, ``pil*.py``.
FILE_NAME = re.compile(r"^[\w*]+\.(?:py|cpp|hpp|toml|xml|\*)$")
#: A room's paragraph of docs/architecture.md starts with its folder in bold: **`sim/rig/`: ...
ROOM = re.compile(r"^\*\*`([\w/]+)/`", re.MULTILINE)


def _matches(pattern: str, tracked, folder: str = "") -> bool:
    """Whether a tracked file matches ``pattern`` (under ``folder``, at any depth there)."""
    rx = re.compile(re.escape(pattern).replace(r"\*", "[^/]*") + "$")
    return any(rx.match(f) if not folder else
               f.startswith(folder + "/") and rx.match(f.rsplit("/", 1)[-1]) for f in tracked)


def _tracked_names():
    return [p.relative_to(ROOT).as_posix() for p in _tracked_files()]


def test_the_map_names_files_that_exist():
    """docs/architecture.md is the map of the house: every path it names, and every file
    name in a room's paragraph, is a file of that room (so the map cannot drift from it)."""
    text = FENCE.sub("", (ROOT / "docs" / "architecture.md").read_text(encoding="utf-8"))
    tracked = [p.relative_to(ROOT).as_posix() for p in _tracked_files()]
    folders = {f.rsplit("/", 1)[0] for f in tracked}
    missing = []
    rooms = list(ROOM.finditer(text))
    for i, room in enumerate(rooms):
        paragraph = text[room.start():text.find("\n\n", room.end())]
        for span in re.findall(r"`([^`]+)`", paragraph):
            if FILE_NAME.match(span) and not _matches(span, tracked, room.group(1)):
                missing.append(f"{span} (in {room.group(1)}/)")
    for span in re.findall(r"`([^`\s]+)`", text):
        path = span.rstrip("/")
        if REPO_PATH.match(span) and not (path in folders or _matches(path, tracked)):
            missing.append(span)
    assert rooms, "no room paragraphs found: the map's format changed"
    assert not missing, "docs/architecture.md names what is not there: " + ", ".join(missing)


def test_the_map_tells_no_history():
    """The map says what is, not how it came to be: no issue numbers, no dates."""
    text = (ROOT / "docs" / "architecture.md").read_text(encoding="utf-8")
    dated = re.findall(r"\b(?:issues? \d+|20\d\d-\d\d-\d\d)\b", text, re.IGNORECASE)
    assert not dated, dated
