"""The writing rules, checked: the README a newcomer reads first stays short and opens with the
two commands; guides stay guides (their API in one screen first, none over 30 KB); every figure
the README quotes links to a table of docs/benchmarks.md that exists, and every benchmark script
has its dated table there; and no file speaks of how or when the project was built (numbered
revisions, sittings, tickets, scratch paths); commit subjects stay under 72 characters, refused
by the commit-msg hook and checked on every commit since the hook exists."""
import re
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
README = ROOT / "README.md"
GUIDES = sorted((ROOT / "docs").glob("*.md"))
DOCS = GUIDES + sorted((ROOT / "docs" / "design").glob("*.md"))
MAX_DOC_BYTES = 30_000
MAX_README_LINES = 150

# Words about the building, not the product. Each pattern is written so that it does not match
# its own source line.
HISTORY = re.compile("|".join([
    r"\bstop [0-9]+", r"\bthis [s]top\b", r"\brevision [0-9]+", r"\bissue [0-9]+",
    r"\bthe [i]ssue's\b", "/" + r"tmp/",
]), re.IGNORECASE)
WORDED = ("README.md", "docs", "mop", "capture", "followers", "characters", "tests", "benchmarks",
          "scripts", "sessions", "recordings", ".ci")
TEXT_SUFFIXES = {".py", ".md", ".toml", ".json", ".sh", ".txt", ".html", ".js", ".css", ".cfg",
                 ""}


def _worded_files():
    for name in WORDED:
        path = ROOT / name
        files = [path] if path.is_file() else sorted(path.rglob("*"))
        for file in files:
            if (file.is_file() and file.suffix in TEXT_SUFFIXES
                    and "__pycache__" not in file.parts and file.stat().st_size < 2_000_000):
                yield file


def _anchor(heading: str) -> str:
    """GitHub's anchor for a heading: lower case, punctuation dropped, spaces to hyphens."""
    return re.sub(r"[^a-z0-9 _-]", "", heading.strip().lower()).replace(" ", "-")


def test_no_file_speaks_of_how_it_was_built():
    hits = []
    for file in _worded_files():
        try:
            text = file.read_text()
        except UnicodeDecodeError:
            continue
        for number, line in enumerate(text.splitlines(), 1):
            match = HISTORY.search(line)
            if match:
                hits.append(f"{file.relative_to(ROOT)}:{number}: {match.group(0)!r}")
    assert not hits, ("say what the code does and why, not when or in which sitting it was "
                      "built (history lives in git):\n" + "\n".join(hits[:40]))


def test_the_readme_is_short_and_opens_with_two_commands():
    lines = README.read_text().splitlines()
    assert len(lines) < MAX_README_LINES, f"README.md has {len(lines)} lines"
    assert lines[0].startswith("# ") and lines[1] == "" and lines[2].strip(), \
        "README.md: the title, then a one-line pitch"
    fence = lines.index("```")
    commands = lines[fence + 1:lines.index("```", fence + 1)]
    assert len(commands) == 2, f"README.md opens with {len(commands)} commands, not two"


@pytest.mark.parametrize("doc", DOCS, ids=lambda p: str(p.relative_to(ROOT)))
def test_no_doc_is_over_30_kb(doc):
    size = doc.stat().st_size
    assert size <= MAX_DOC_BYTES, (f"{doc.relative_to(ROOT)} is {size / 1000:.0f} KB: move "
                                   "measurements to docs/benchmarks.md and decisions to "
                                   "docs/design/, or split the guide")


@pytest.mark.parametrize("guide", [g for g in GUIDES if g.name != "benchmarks.md"],
                         ids=lambda p: p.name)
def test_every_guide_opens_with_its_api_in_one_screen(guide):
    headings = [line for line in guide.read_text().splitlines() if line.startswith("## ")]
    assert headings and headings[0] == "## API in one screen", \
        f"{guide.name}: its first section is {headings[:1]}, not '## API in one screen'"


def test_every_readme_link_into_the_docs_lands():
    text = README.read_text()
    links = re.findall(r"\]\((docs/[^)#\s]+)(?:#([^)\s]+))?\)", text)
    assert links
    figures = text[text.index("## Figures"):].split("\n## ")[0]
    assert all("docs/benchmarks.md#" in row for row in figures.splitlines()
               if row.startswith("| [")), "every README figure links to its benchmarks table"
    broken = []
    for target, anchor in links:
        path = ROOT / target
        if not path.exists():
            broken.append(target)
        elif anchor and path.suffix == ".md":
            anchors = {_anchor(line.lstrip("#")) for line in path.read_text().splitlines()
                       if line.startswith("#")}
            if anchor not in anchors:
                broken.append(f"{target}#{anchor}")
    assert not broken, "README links that land nowhere: " + ", ".join(broken)


def test_every_benchmark_script_has_a_dated_table():
    headings = [line for line in (ROOT / "docs" / "benchmarks.md").read_text().splitlines()
                if line.startswith("## ")]
    missing = [script.name for script in sorted((ROOT / "benchmarks").glob("*.py"))
               if not any(re.search(rf"`benchmarks/{re.escape(script.name)}` \(\d{{4}}-\d\d-\d\d\)",
                                    heading) for heading in headings)]
    assert not missing, ("benchmarks without a '## Name — `benchmarks/x.py` (YYYY-MM-DD)' table "
                         "in docs/benchmarks.md: " + ", ".join(missing))


HOOK = ROOT / "scripts" / "hooks" / "commit-msg"


@pytest.mark.parametrize("message, refused", [
    ("Capture: a short subject\n\nFigures in the body, as long as they like to be.\n", None),
    ("x" * 71 + "\n", None),
    ("# a comment line git strips\nSessions: short\n", None),
    ("x" * 72 + "\n", "the subject is 72 characters"),
    ("Sessions: a subject\nthat runs on\n", "leave a blank line after the subject"),
])
def test_the_commit_hook_refuses_long_subjects(tmp_path, message, refused):
    path = tmp_path / "COMMIT_EDITMSG"
    path.write_text(message)
    result = subprocess.run([str(HOOK), str(path)], capture_output=True, text=True)
    assert result.returncode == (0 if refused is None else 1)
    assert (refused or "") in result.stderr


def _git(*args):
    return subprocess.run(["git", "-C", str(ROOT), *args], capture_output=True, text=True,
                          check=True).stdout


@pytest.mark.skipif(shutil.which("git") is None or not (ROOT / ".git").exists(),
                    reason="not a git checkout")
def test_every_commit_since_the_hook_has_a_short_subject():
    added = _git("log", "--diff-filter=A", "--format=%H", "--", "scripts/hooks/commit-msg")
    if not added.strip():
        pytest.skip("the hook is not committed yet")
    first = added.split()[-1]
    messages = _git("log", "--format=%H%x1f%B%x1e", f"{first}~1..HEAD").split("\x1e")
    long = []
    for entry in filter(str.strip, messages):
        sha, body = entry.strip().split("\x1f", 1)
        lines = body.splitlines() + [""]
        if len(lines[0]) >= 72 or lines[1].strip():
            long.append(f"{sha[:9]} {lines[0][:60]}")
    assert not long, "commit subjects of 72 characters or more, or without a blank line: " + (
        "; ".join(long))
