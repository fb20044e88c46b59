"""The one-way house: what each package may import (DESIGN.md, README "Architecture")."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_the_geometry_core_imports_no_torch() -> None:
    # A fresh interpreter: this test process may have imported torch for other tests.
    code = ("import sys, dataset.geometry; "
            "heavy = sorted(m for m in ('torch', 'flask', 'sqlalchemy') if m in sys.modules); "
            "assert not heavy, heavy")
    result = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
