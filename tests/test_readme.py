"""The README and the documentation say what is so: their Python examples
run as written, so the API they show is the API there is; the schema error
they quote is the one the command prints; the README stays a front door of
at most 300 lines; every relative link goes to a file (and a heading) that
is there."""

import re
import subprocess
import sys
import unicodedata
from pathlib import Path
from urllib.parse import unquote

import pytest

ROOT = Path(__file__).resolve().parent.parent
README = ROOT / "README.md"
DOCS = ROOT / "docs"
PAGES = [README, *sorted(DOCS.rglob("*.md"))]


def name(page: Path) -> str:
    return page.relative_to(ROOT).as_posix()


EXAMPLES = [
    (name(page), code) for page in PAGES for code in re.findall(r"```python\n(.*?)```", page.read_text(), flags=re.S)
]


def test_the_documentation_has_python_examples():
    assert len(EXAMPLES) >= 3


@pytest.mark.slow  # the capture-the-flag example solves two 31^4 sets, a quarter of a minute
@pytest.mark.parametrize(("page", "code"), EXAMPLES, ids=[f"{page}-{k}" for k, (page, _) in enumerate(EXAMPLES)])
def test_a_documented_example_runs(page, code):
    exec(compile(code, page, "exec"), {})


def test_the_quoted_schema_error_is_what_the_command_prints(tmp_path):
    page = (DOCS / "reference" / "scenarios.md").read_text()
    quoted = re.search(r"^\$ bearcat simulate game\.toml\n(bearcat: error: game\.toml: .*)$", page, flags=re.M)
    assert quoted, "the scenarios page quotes a schema error"
    scenario = (ROOT / "bearcat" / "scenarios" / "data" / "fake-out.toml").read_text()
    (tmp_path / "game.toml").write_text(scenario.replace('behaviour = "fake-out"', 'behaviour = "fakeout"', 1))
    run = subprocess.run(
        [sys.executable, "-m", "bearcat", "simulate", "game.toml"], cwd=tmp_path, capture_output=True, text=True
    )
    assert run.returncode == 2
    assert run.stderr.strip() == quoted.group(1)


def test_the_readme_is_a_front_door():
    lines = README.read_text().splitlines()
    assert len(lines) <= 300, f"README.md has {len(lines)} lines; the rest belongs in docs/"
    commands = re.findall(r"```bash\n(.*?)\n```", README.read_text(), flags=re.S)[:2]
    assert commands == [
        "python3 -m venv .venv && . .venv/bin/activate && pip install . && bearcat run fake-out",
        'python3 -m venv .venv && . .venv/bin/activate && pip install -e ".[test]" && python -m pytest',
    ]


def unfenced(text: str) -> str:
    """The text outside fenced code blocks, where headings are headings."""
    return re.sub(r"^```.*?^```", "", text, flags=re.S | re.M)


def prose(text: str) -> str:
    """The text outside fenced code blocks and inline code, where links are links."""
    return re.sub(r"`[^`\n]*`", "", unfenced(text))


def slug(heading: str) -> str:
    """A heading's anchor as MkDocs (Python-Markdown's toc) and GitHub both make it for these pages."""
    text = re.sub(r"`([^`]*)`", r"\1", heading)
    text = re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", text)
    text = unicodedata.normalize("NFKD", text).encode("ascii", "ignore").decode()
    text = re.sub(r"[^\w\s-]", "", text).strip().lower()
    return re.sub(r"[-\s]+", "-", text)


def anchors(page: Path) -> set[str]:
    return {slug(h) for h in re.findall(r"^#{1,6} (.+?)\s*#*$", unfenced(page.read_text()), flags=re.M)}


LINKS = [
    (name(page), target)
    for page in PAGES
    for target in re.findall(r"\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)", prose(page.read_text()))
    + re.findall(r"<img [^>]*src=\"([^\"]+)\"", prose(page.read_text()))
    if not re.match(r"[a-z][a-z0-9+.-]*:", target)  # http:, https:, mailto: ...
]


def test_the_pages_have_relative_links():
    assert any(page == "README.md" for page, _ in LINKS)
    assert any(page.startswith("docs/") for page, _ in LINKS)


@pytest.mark.parametrize(("page", "target"), LINKS, ids=[f"{page}->{target}" for page, target in LINKS])
def test_a_relative_link_goes_to_a_file_that_is_there(page, target):
    path, _, fragment = unquote(target).partition("#")
    linked = (ROOT / page).parent / path if path else ROOT / page
    assert linked.resolve().is_file(), f"{page} links to {target}, which is not there"
    if fragment and linked.suffix == ".md":
        assert fragment in anchors(linked), f"{page} links to {target}, which has no heading {fragment!r}"
