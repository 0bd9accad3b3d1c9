"""The places the tests read: the repository, the test tree, its helpers and its data files.

One definition, so a test file can move between folders without counting parents of its ``__file__``."""

from __future__ import annotations

from pathlib import Path

TESTS = Path(__file__).resolve().parents[1]
REPO = TESTS.parent
HELPERS = TESTS / "helpers"
DATA = TESTS / "data"
