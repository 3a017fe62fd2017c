"""Paths the tests read from the repository, found from this file (so a test file can move)."""
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
TEST_DATA = REPO / "tests" / "data"
FLOWSHEETS = REPO / "flowsheets"
EXAMPLES = REPO / "examples"
DOCS = REPO / "docs"
