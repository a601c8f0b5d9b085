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


# What a user is told to install: the pages, the rooms' messages and docstrings, the scripts, the Makefile (not the
# tests, whose fakes name extras nobody declares).
_INSTALLERS = PAGES + sorted(p for d in ("sdk", "scene", "capture", "metrics", "evaluate", "train", "export", "cli",
                                         "conformance", "plugins", "bench", "examples")
                             for p in (ROOT / d).rglob("*.py")) + [ROOT / "Makefile", ROOT / "pyproject.toml"]
_EXTRA = re.compile(r"\brtp\[([\w,-]+)\]")
# `pip install rtp` / `pip install -U rtp` by its bare name: PyPI's rtp, another project (`rtp @ git+URL` is rtp's).
_PYPI_RTP = re.compile(r"pip install (?:-U |--upgrade )?['\"`]?rtp(?![\w\[.-])(?!\s*@)")


def test_every_extra_named_is_one_pyproject_declares() -> None:
    """Every `rtp[extra]` the docs and messages name is an extra of pyproject.toml, and none says to install rtp by
    its bare name, PyPI's other project. load_mesh_file and the BSP texture reader said `pip install 'rtp[scenes]'`
    (no such extra: pip warns and installs nothing, and `rtp capture --scene room.glb` without trimesh printed that
    as its one-line error); a dataset of a newer format said `upgrade rtp (pip install -U rtp)`."""
    import tomllib

    extras = set(tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["optional-dependencies"])
    named: dict[str, set[str]] = {}
    to_pypi = []
    for path in _INSTALLERS:
        text = path.read_text(encoding="utf-8", errors="replace")
        for group in _EXTRA.findall(text):
            for extra in group.split(","):
                named.setdefault(extra, set()).add(str(path.relative_to(ROOT)))
        to_pypi += [f"{path.relative_to(ROOT)}: {line.strip()}" for line in text.splitlines()
                    if _PYPI_RTP.search(line) and "another project" not in line]
    assert {"capture", "ray", "train", "export", "metrics", "moderngl", "pyrender"} <= set(named)  # the scan finds them
    unknown = {e: sorted(where) for e, where in named.items() if e not in extras}
    assert not unknown, f"extras pyproject.toml does not declare: {unknown}"
    assert not to_pypi, "told to install PyPI's rtp (another project):\n" + "\n".join(to_pypi)
    assert _PYPI_RTP.search("upgrade rtp (pip install -U rtp)") and not _PYPI_RTP.search('pip install "rtp @ git+URL"')


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


# docs/results.md's claims about the shipped models' test figures agree with the tables they summarise (its
# own, and the published `rtp evaluate` files under docs/results/). Each of these held a stale or wrong claim:
# "All five lie inside the paper's overall 70-94%" with PSNR at 95.4%, savings ranges and baseline comparisons
# left at the one-threshold files after the thresholds per rate shipped.
RESULTS = DOCS / "results.md"
SHIPPED = ("jnyang", "psnr", "flip", "jnflip", "lpips", "jnyang-reuse")
_NUM = re.compile(r"-?\d+(?:\.\d+)?")


def _table_after(text: str, marker: str) -> list[list[str]]:
    """The cells of each body row of the first Markdown table at or after ``marker``."""
    start = text.index(marker)
    lines = text[start:].splitlines()
    first = next(i for i, line in enumerate(lines) if line.startswith("|"))
    rows = []
    for line in lines[first + 2:]:  # past the header and its |---| line
        if not line.startswith("|"):
            break
        rows.append([c.strip().strip("*").strip() for c in line.strip("|").split("|")])
    return rows


def _floats(cell: str) -> list[float]:
    return [float(x) for x in _NUM.findall(cell)]


def _span(values: list[float]) -> tuple[str, str]:
    return f"{min(values):.1f}", f"{max(values):.1f}"


def _headline() -> dict[str, list[str]]:
    rows = _table_after(RESULTS.read_text(encoding="utf-8"), "| model | R² all tiles | R² unseen tiles |")
    return {r[0]: r for r in rows}


def test_results_headline_says_which_models_lie_outside_the_papers_ranges() -> None:
    text = RESULTS.read_text(encoding="utf-8")
    rows = _headline()
    assert set(SHIPPED) <= set(rows)
    five = SHIPPED[:5]
    r2 = {m: (_floats(rows[m][1])[0], _floats(rows[m][3])[0]) for m in five}  # with the margin; the paper's R²
    outside = [m for m in five if not all(70 <= v <= 94 for v in r2[m])]
    claim = re.search(r"(\w+) of the five lie inside the paper's overall 70-94%", text)
    assert claim is not None
    words = {"None": 0, "One": 1, "Two": 2, "Three": 3, "Four": 4, "All": 5}
    assert words[claim.group(1)] == 5 - len(outside), (claim.group(0), outside)
    after = text[claim.end():claim.end() + 200].upper()
    assert all(name.upper() in after for name in outside), (outside, after)
    # and each metric's own range (the column before the last): the paper's R² above it, named
    top = {m: float(rows[m][4].rstrip("%").split("-")[1]) for m in five}  # "78-94%": 94
    above = [m for m in five if r2[m][1] > top[m]]
    own = re.search(r"By the paper's R², ([^.]*?) (?:is|are) also above their own metric's range", text)
    assert own is not None
    assert sorted(n.upper() for n in re.split(r",\s*|\s+and\s+", own.group(1))) == sorted(n.upper() for n in above)


def test_results_which_r2_gains_over_the_issues_start_are_its_tables() -> None:
    text = RESULTS.read_text(encoding="utf-8")
    rows = {r[0]: r for r in _table_after(text, "| test split, 80 samples | R² all / seen / unseen %")}
    with_margin, without, saved = [], [], {}
    for m in SHIPPED[:5]:
        start, now = rows[f"{m}, at the issue's start"], rows[f"{m}, shipped"]
        with_margin += [b - a for a, b in zip(_floats(start[1]), _floats(now[1]))]
        without += [b - a for a, b in zip(_floats(start[2]), _floats(now[2]))]
        saved[m] = [b - a for a, b in zip(_floats(start[3])[:3], _floats(now[3])[:3])]  # at 1, 2 and 5%
    claim = re.search(r"by (\d+\.\d)-(\d+\.\d) points with the margin and (\d+\.\d)-(\d+\.\d) without it", text)
    assert claim is not None and claim.groups() == _span(with_margin) + _span(without), claim
    claim = re.search(r"JNYang (\d+\.\d)-(\d+\.\d) points at 1-5%, LPIPS (\d+\.\d)-(\d+\.\d)", text)
    assert claim is not None and claim.groups() == _span(saved["jnyang"]) + _span(saved["lpips"]), claim


def _matched(model: str) -> dict[str, list[str]]:
    """The "At matched quality" rows of the published `make evaluate` file of ``model``."""
    text = (DOCS / "results" / f"evaluation-{model}.md").read_text(encoding="utf-8")
    return {r[0]: r for r in _table_after(text, "## At matched quality")}


def test_results_baselines_at_the_shipped_models_defaults_are_the_published_files() -> None:
    text = RESULTS.read_text(encoding="utf-8")
    headline = _headline()
    files = {m: _matched(m) for m in SHIPPED}
    fails = [_floats(headline[m][5])[0] for m in SHIPPED]
    assert [float(files[m]["model"][1]) for m in SHIPPED] == fails  # the headline's default = the files'
    claim = re.search(r"six fail (\d+\.\d)-(\d+\.\d)%", text)
    assert claim is not None and claim.groups() == _span(fails), claim
    model = [float(files[m]["model"][2]) for m in SHIPPED]
    yang_unseen = [float(files[m]["yang2019-unseen-1x1"][2]) for m in SHIPPED]
    claim = re.search(r"saving (\d+\.\d)-(\d+\.\d)% where the models save (\d+\.\d)-(\d+\.\d)%", text)
    assert claim is not None and claim.groups() == _span(yang_unseen) + _span(model), claim
    # "more rarely than Yang 2019 can at any setting, and every one but JNYang more rarely than FidelityFX"
    assert all(files[m]["yang2019"][2] == "-" for m in SHIPPED)
    assert [m for m in SHIPPED if files[m]["fidelityfx"][2] != "-"] == ["jnyang"]
    assert "every one but JNYang more rarely than FidelityFX" in text.replace("\n", " ")


def test_tables_made_from_evaltest_shipped_quote_its_current_savings() -> None:
    """A table whose command reads data/evaltest-shipped quotes the shipped files' work saved as "Which R²" does,
    or says that its row is of the one-threshold file (LPIPS's grow-2 table kept the one-threshold savings under
    "shipped" after the file changed)."""
    text = RESULTS.read_text(encoding="utf-8")
    which = _table_after(text, "| test split, 80 samples | R² all / seen / unseen %")
    current = {r[1]: _floats(r[3])[:4] for r in which if r[0].endswith(", shipped")}
    assert len(current) == len(SHIPPED)
    checked = 0
    for block in re.finditer(r"```bash\n(.*?)```", text, re.S):
        if "data/evaltest-shipped/evaluation.json" not in block.group(1):
            continue
        for row in _table_after(text[block.end():], "|"):
            if "shipped" not in row[0] or "one threshold" in row[0]:
                continue
            for cell in row[:-1]:
                if cell in current and len(_floats(row[-1])) >= 4:
                    checked += 1
                    assert _floats(row[-1])[:4] == current[cell], row
    assert checked >= len(SHIPPED), checked
