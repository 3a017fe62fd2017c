"""What a reader sees carries no tracker numbers and no dangling references: no "issue N"
in the library, the command-line help, the docs, the examples or the README; no pointer to
an EQUATIONS.md that is not in the repository (the equations are docs/equations.md)."""
import contextlib
import io
import re

import pytest

from millflow.cli import build_parser
from tests import paths

ISSUE = re.compile(r"\bissues? #?\d+", re.I)
TEXT = [p for folder in ("millflow", "rtd", "docs", "flowsheets", "examples")
        for p in (paths.REPO / folder).rglob("*") if p.suffix in (".py", ".md", ".toml", ".c", ".h")]
TEXT.append(paths.REPO / "README.md")


@pytest.mark.parametrize("path", TEXT, ids=lambda p: str(p.relative_to(paths.REPO)))
def test_no_issue_numbers_or_dangling_equation_file(path):
    text = path.read_text(encoding="utf-8")
    assert not ISSUE.search(text), ISSUE.search(text).group(0)
    assert "EQUATIONS.md" not in text


def test_cli_help_has_no_issue_numbers():
    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    for name, p in sub.choices.items():
        buf = io.StringIO()
        with contextlib.redirect_stdout(buf):
            p.print_help()
        assert not ISSUE.search(buf.getvalue()), (name, ISSUE.search(buf.getvalue()).group(0))


def test_gallery_shows_every_example_with_its_input_and_report():
    page = (paths.DOCS / "gallery.md").read_text(encoding="utf-8")
    for toml in sorted(paths.FLOWSHEETS.glob("*.toml")):
        assert f"(downloads/{toml.name})" in page, toml.name  # the input, downloadable
        assert f"(gallery/reports/{toml.stem}.html)" in page, toml.name
        assert (paths.DOCS / "gallery" / "reports" / f"{toml.stem}.html").is_file()
        assert (paths.DOCS / "gallery" / "img" / f"{toml.stem}-flowsheet.svg").is_file()  # the report's drawing
    for job in ("run", "tracer", "fit", "scaleup", "sweep", "survey"):  # one run per daily job, its output shown
        assert (paths.DOCS / "gallery" / "out" / f"{job}.txt").read_text().startswith("$ millflow ")
    # the survey balance: its inputs downloadable, its report published
    assert "(downloads/survey.toml)" in page and "(downloads/circuit.toml)" in page
    assert "(gallery/reports/survey_balance.html)" in page
    assert (paths.DOCS / "gallery" / "reports" / "survey_balance.html").is_file()
