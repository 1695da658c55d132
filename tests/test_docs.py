"""The documentation's own rules: a short README, results that cannot go stale, the citation.

The no-stale-numbers rule: README.md, every Markdown page under docs/ and every docstring of the
packages are read with code (fenced blocks, inline code), mathematics ($…$, $$…$$, ``{math}``
blocks; in a docstring its ``::`` literal blocks), HTML comments, link targets, section numbers and
arXiv identifiers left out, and with each decision
record's "At the decision" section left out (a dated record of what was measured when the choice
was made; it must name the version and the date). Every decimal number left (``0.047``, ``2.5``,
``1.9e-11``) must be the value of some number in a ``docs/results/*.json`` file, rounded to the
digits shown: a result is published by a benchmark, not typed. Integers are not checked: they are
counts, sizes and settings (2 kHz, 50 points, 6 replicas). A value a docstring takes from a
source is written as the code's literal (````83.3````).
"""

from __future__ import annotations

import ast
import json
import re
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
RESULTS = DOCS / "results"
DECISIONS = DOCS / "design" / "decisions"

NUMBER = re.compile(r"(?<![\w.\-])-?\d+\.\d+(?:e[-+]?\d+)?(?![\w.])")
FENCE = re.compile(r"^(```|~~~)[^\n]*\n.*?^\1\s*$", re.S | re.M)
INLINE_CODE = re.compile(r"``.+?``|`[^`\n]+`")
MATH = re.compile(r"\$\$.+?\$\$|\$[^$\n]+\$", re.S)
COMMENT = re.compile(r"<!--.*?-->", re.S)
LINK_TARGET = re.compile(r"\]\([^)]*\)")
ARXIV = re.compile(r"arXiv:\d{4}\.\d{4,5}|§\s*[\d.]+\d")
#: The packages whose docstrings the rule reads.
PACKAGES = ("rhmpc", "sim", "predictors", "robots")
AT_DECISION = re.compile(r"^(#+) At the decision\s*$(.*?)(?=^#{1,3} |\Z)", re.S | re.M)
HISTORY = re.compile(r"issue[ -]?[0-9]|\bsession\b|closing\s+note", re.I)


def pages() -> list[Path]:
    return [ROOT / "README.md", *sorted(p for p in DOCS.rglob("*.md")
                                        if "_build" not in p.parts and "gallery" not in p.parts)]


def prose(text: str) -> str:
    """``text`` without code, mathematics, comments and link targets."""
    for pattern in (FENCE, COMMENT, INLINE_CODE, MATH, LINK_TARGET, ARXIV):
        text = pattern.sub(" ", text)
    return text


def leaves(obj):
    if isinstance(obj, dict):
        for v in obj.values():
            yield from leaves(v)
    elif isinstance(obj, list):
        for v in obj:
            yield from leaves(v)
    elif isinstance(obj, int | float) and not isinstance(obj, bool):
        yield float(obj)


def results() -> dict[str, dict]:
    return {p.stem: json.loads(p.read_text()) for p in sorted(RESULTS.glob("*.json"))}


def held_strings() -> set[str]:
    """Every number of every results file, formatted as a page could show it."""
    out = set()
    for doc in results().values():
        for v in leaves(doc):
            for d in range(0, 7):
                out.add(f"{v:.{d}f}")
                out.add(f"{v:.{d}e}")
    return out


def test_readme_is_short() -> None:
    assert len((ROOT / "README.md").read_text().splitlines()) <= 200


def test_every_number_on_a_page_is_held_by_a_results_file() -> None:
    held = held_strings()
    missing = []
    for page in pages():
        text = page.read_text()
        if page.parent == DECISIONS:
            text = AT_DECISION.sub(" ", text)
        for line in prose(text).splitlines():
            for m in NUMBER.finditer(line):
                if m.group(0).lstrip("-") not in held:
                    missing.append(f"{page.relative_to(ROOT)}: {m.group(0)} in {line.strip()!r}")
    assert not missing, "numbers no results file holds:\n" + "\n".join(missing)


def without_literal_blocks(doc: str) -> str:
    """A docstring without its reStructuredText literal blocks (the indented lines after a line
    that ends in ``::``)."""
    out, indent = [], None
    for line in doc.splitlines():
        depth = len(line) - len(line.lstrip())
        if indent is not None and (not line.strip() or depth > indent):
            continue
        indent = depth if line.rstrip().endswith("::") else None
        out.append(line)
    return "\n".join(out)


def docstrings() -> list[tuple[str, str]]:
    """(where, text) of every module, class and function docstring of the packages."""
    out = []
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            for node in ast.walk(ast.parse(path.read_text())):
                if isinstance(node, ast.Module | ast.ClassDef | ast.FunctionDef
                              | ast.AsyncFunctionDef) and (doc := ast.get_docstring(node)):
                    name = getattr(node, "name", "module")
                    out.append((f"{path.relative_to(ROOT)}:{name}", without_literal_blocks(doc)))
    return out


@pytest.mark.slow
def test_every_number_in_a_docstring_is_held_by_a_results_file() -> None:
    held = held_strings()
    missing = [f"{where}: {m.group(0)} in {line.strip()!r}"
               for where, doc in docstrings() for line in prose(doc).splitlines()
               for m in NUMBER.finditer(line) if m.group(0).lstrip("-") not in held]
    assert not missing, "numbers in docstrings no results file holds:\n" + "\n".join(missing)


def test_the_rule_catches_a_typed_number() -> None:
    held = held_strings()
    typed = prose("The RMS error is 0.0471828 mm (`0.5 ms` in code and $0.25$ in math are fine).")
    assert [m.group(0) for m in NUMBER.finditer(typed)] == ["0.0471828"]
    assert "0.0471828" not in held


def test_decision_records_date_what_they_measured_then() -> None:
    records = [p for p in DECISIONS.glob("*.md") if p.name != "index.md"]
    assert len(records) >= 8
    for record in records:
        text = record.read_text()
        for heading in ("## Context", "## Decision", "## Consequences", "## Measured"):
            assert heading in text, f"{record.name} lacks {heading}"
        for m in AT_DECISION.finditer(text):
            assert re.match(r"\s*Version \d+\.\d+\.\d+, \d{4}-\d{2}-\d{2}", m.group(2)), (
                f"{record.name}: 'At the decision' must start with the version and the date")


def test_results_files_record_their_provenance() -> None:
    docs = results()
    assert docs, "no results files: run python benchmarks/run_all.py --quick"
    for name, doc in docs.items():
        for key in ("command", "version", "date", "data"):
            assert doc.get(key) not in (None, ""), f"{name}.json lacks {key}"
        assert doc["machine"]["cores"] >= 1 and doc["machine"]["gain_tick_us"] > 0
        md = (RESULTS / f"{name}.md").read_text()
        assert doc["command"] in md and doc["version"] in md and doc["date"] in md


def test_every_include_of_a_results_file_resolves() -> None:
    for page in pages():
        for m in re.finditer(r"```\{include\} ([^\n]+)\n((?::[^\n]*\n)*)", page.read_text()):
            target = (page.parent / m.group(1).strip()).resolve()
            assert target.is_file(), f"{page.relative_to(ROOT)} includes a missing {target}"
            for opt in re.findall(r":(?:start-after|end-before): (.+)", m.group(2)):
                assert opt.strip() in target.read_text(), f"{page.name}: no {opt} in {target}"


def test_readme_tables_match_their_results_files() -> None:
    readme = (ROOT / "README.md").read_text()
    blocks = re.findall(r"<!-- results:(\w+) -->\n(.*?)<!-- /results:\1 -->", readme, re.S)
    assert blocks, "the README has no generated results table"
    for name, body in blocks:
        assert body == (RESULTS / f"{name}.md").read_text(), (
            f"README's {name} table is stale: run python benchmarks/run_all.py --only {name}")


def test_readme_figure_is_tracked_and_present() -> None:
    figure = DOCS / "_static" / "tracking-run.png"
    assert figure.is_file() and "docs/_static/tracking-run.png" in (ROOT / "README.md").read_text()


def test_gallery_has_at_least_four_examples_with_a_title() -> None:
    examples = sorted((ROOT / "examples").glob("plot_*.py"))
    assert len(examples) >= 4
    for ex in examples:
        doc = ex.read_text().split('"""')[1].strip().splitlines()
        assert len(doc) >= 2 and set(doc[1]) == {"="}, f"{ex.name}: no sphinx-gallery title"


def test_citation_cites_the_software_and_four_papers() -> None:
    yaml = pytest.importorskip("yaml")
    cff = yaml.safe_load((ROOT / "CITATION.cff").read_text())
    assert cff["type"] == "software" and cff["license"] == "BSD-3-Clause"
    assert len(cff["references"]) == 4
    assert {r["year"] for r in cff["references"]} == {2008, 2009, 2010, 2013}
    assert "BSD 3-Clause" in (ROOT / "LICENSE").read_text()


def test_documentation_tells_no_development_history() -> None:
    try:
        files = subprocess.run(["git", "ls-files"], cwd=ROOT, capture_output=True, text=True,
                               check=True).stdout.split()
    except (OSError, subprocess.CalledProcessError):
        pytest.skip("not a git checkout")
    ours = [f for f in files if f.split("/")[0] in {"docs", "examples", "benchmarks"}
            or f in {"README.md", "CHANGELOG.md", "LICENSE", "CITATION.cff", ".ci/run"}]
    hits = [f"{f}: {line.strip()}" for f in ours if (ROOT / f).suffix not in {".png", ".json"}
            for line in (ROOT / f).read_text(errors="replace").splitlines()
            if HISTORY.search(line)]
    assert not hits, "\n".join(hits)
