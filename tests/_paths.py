"""Where the tests find the repository and their data, whichever folder of ``tests/`` they sit in."""

from __future__ import annotations

from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
"""The repository's root (its README, docs/, configs/)."""
DATA = ROOT / "tests" / "data"
"""The tests' data: real flight logs, a published design, the reference runs (each with its licence)."""
