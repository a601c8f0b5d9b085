"""The documentation's cross-references resolve: every Markdown link or image in docs/ and the README
names a file that exists, and every reference to a section by name (``docs/results.md "LPIPS on
RGB"``, in the docs, the code and the recipes) names a heading or a bold paragraph lead of that file.
The pages cite each other by section name (results.md alone has about a hundred such sections), so a
renamed heading or a page copied elsewhere breaks them silently."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
PAGES = sorted(DOCS.rglob("*.md")) + [ROOT / "README.md"]
# Where sections are cited by name besides the pages: the code, the recipes and the make targets.
CITERS = PAGES + sorted(p for d in ("sdk", "scene", "capture", "metrics", "evaluate", "train", "export", "cli",
                                    "plugins", "bench", "examples", "tests")
                        for p in (ROOT / d).rglob("*")
                        if p.suffix in (".py", ".yaml") and p.name != Path(__file__).name) + [ROOT / "Makefile"]

_LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s#]+)(?:#[^)]*)?\)")
# docs/NAME.md "Title", NAME.md, "Title", NAME.md section "Title"; the title starts with a word character.
_CITE = re.compile(r"((?:docs/)?(?:results/)?[\w-]+)\.md,?\s+(?:section\s+)?\"(\w[^\"\n()\[\]=]{1,150})\"")
_HEADING = re.compile(r"^#+\s+(.+?)\s*$")
_BOLD = re.compile(r"\*\*([^*]+)\*\*")


def _anchors(page: Path) -> set[str]:
    """A page's headings and bold phrases (results.md's studies start with a bold name)."""
    found: set[str] = set()
    for line in page.read_text(encoding="utf-8").splitlines():
        m = _HEADING.match(line)
        if m:
            found.add(m.group(1))
        found.update(b.strip() for b in _BOLD.findall(line))
    return found


def _page(name: str) -> Path | None:
    """The page a citation names: ``docs/x``, ``results/x`` (docs/results/), or a bare page name."""
    name = name.removeprefix("docs/")
    for candidate in (DOCS / f"{name}.md", ROOT / f"{name}.md"):
        if candidate.is_file():
            return candidate
    return None


def test_pages_are_found() -> None:
    assert len(PAGES) > 15 and any(p.name == "results.md" for p in PAGES)
    assert len(CITERS) > 200


@pytest.mark.parametrize("page", PAGES, ids=[str(p.relative_to(ROOT)) for p in PAGES])
def test_links_name_files_that_exist(page: Path) -> None:
    text = page.read_text(encoding="utf-8")
    missing = [target for target in _LINK.findall(text)
               if not target.startswith(("http://", "https://", "mailto:")) and not (page.parent / target).exists()]
    assert not missing, f"{page.relative_to(ROOT)} links to files that are not there: {missing}"


def test_section_citations_name_sections_that_exist() -> None:
    anchors: dict[Path, set[str]] = {}
    broken, checked = [], 0
    for citer in CITERS:
        for name, title in _CITE.findall(citer.read_text(encoding="utf-8", errors="replace")):
            page = _page(name)
            if page is None:  # a file the code writes (``play.md``), not a page
                continue
            checked += 1
            names = anchors.setdefault(page, _anchors(page))
            if not any(a.startswith(title.rstrip(". ")) for a in names):
                broken.append(f"{citer.relative_to(ROOT)}: {name}.md \"{title}\"")
    assert checked > 80, checked  # the pattern still finds the citations
    assert not broken, "citations of sections that do not exist:\n" + "\n".join(broken)


def test_a_broken_citation_is_found(tmp_path: Path) -> None:
    text = 'as measured (docs/results.md "A section nobody wrote") and (docs/results.md "Which R²")'
    found = _CITE.findall(text)
    assert found == [("docs/results", "A section nobody wrote"), ("docs/results", "Which R²")]
    names = _anchors(DOCS / "results.md")
    assert any(a.startswith("Which R²") for a in names)
    assert not any(a.startswith("A section nobody wrote") for a in names)


#: Dotted names that start with ``rtp.`` but are not Python objects.
NOT_OBJECTS = {
    "rtp.adapters": "the entry-point group adapters register in",
    "rtp.metadata": "the ONNX metadata_props key of a model's metadata",
    "rtp.tail": "the ONNX metadata_props key of a split network's tail",
    "rtp.demo": "a logger's name",
    "rtp.x._y": "architecture.md's example of a private module",
    "rtp.sdk._channels_then": "bench/planes.py's name for an old revision's module",
    "rtp.sdk._reproject_then": "bench/input_planes.py's name for an old revision's module",
    "rtp.sdk._planes_then": "bench/input_planes.py's name for an old revision's module",
    "rtp.plugins.no_such_plugin": "tests/test_adapters.py's entry point of an rtp plugin that cannot import",
}
_DOTTED = re.compile(r"(?<![\w./-])rtp(?:\.[A-Za-z_]\w*)+")


def _resolves(name: str) -> bool:
    """``name`` is a module of rtp or an attribute path inside one."""
    import importlib

    parts = name.split(".")
    for i in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:i]))
        except ImportError:
            continue
        for attr in parts[i:]:
            if not hasattr(obj, attr):
                return False
            obj = getattr(obj, attr)
        return True
    return False


def test_dotted_names_of_rtp_objects_exist() -> None:
    """Every ``rtp.room.name`` the docs, docstrings and comments mention is a module or an object
    there (``rtp.plugins.moderngl._scene.Scene`` outlived its move to ``rtp.scene`` in five places)."""
    found: dict[str, set[str]] = {}
    for citer in CITERS:
        for name in _DOTTED.findall(citer.read_text(encoding="utf-8", errors="replace")):
            found.setdefault(name.rstrip("."), set()).add(str(citer.relative_to(ROOT)))
    assert len(found) > 100, len(found)
    missing = {n: sorted(f) for n, f in found.items() if n not in NOT_OBJECTS and not _resolves(n)}
    assert not missing, f"names that are no module or object of rtp: {missing}"
    assert not _resolves("rtp.plugins.moderngl._scene") and _resolves("rtp.scene.Scene")


def test_make_help_names_every_target() -> None:
    """`make help` lists every phony target in a line; a target added without its line is found here."""
    text = (ROOT / "Makefile").read_text()
    phony = re.search(r"^\.PHONY: (.*)$", text, re.M)
    assert phony is not None
    helped = set(re.findall(r'^\t@echo "make ([a-z-]+)', text, re.M)) | set(re.findall(r'@echo "make [a-z-]+ \| ([a-z-]+)',
                                                                                       text, re.M))
    helped |= {"help"} if "help:" in text else set()
    missing = [t for t in phony.group(1).split() if t not in helped]
    assert not missing, f"make help names no line for: {', '.join(missing)}"


def test_the_training_pages_dataset_is_make_datasets() -> None:
    """docs/training.md's capture commands are `make dataset`'s, the shipped models' data (it said --per-scene 20
    where the Makefile and the shipped models' 1,224 + 72 samples are 12 a map and profile: 1.7 times the data and
    the memory its training holds)."""
    make = dict(re.findall(r"^([A-Z_]+)\s*\?=\s*(\S+)", (ROOT / "Makefile").read_text(), re.M))
    page = (ROOT / "docs" / "training.md").read_text()
    for split, key in (("train", "PER_SCENE"), ("validation", "VAL_PER_SCENE")):
        m = re.search(rf"^rtp capture --split {split} --per-scene (\d+) --size (\S+) ", page, re.M)
        assert m is not None, split
        assert m.groups() == (make[key], make["SIZE"]), (split, m.groups())
