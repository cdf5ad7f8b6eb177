"""The paths and command the test files share: the project root and the ``spar`` command.

Imported as ``from paths import ROOT, SPAR``, like the other helpers here (craig_reference,
motion_fake): pytest puts tests/ on sys.path, and ``python tests/units_fixture.py`` does too."""
from __future__ import annotations

import sys
from pathlib import Path

#: The project root (where kb/, src/ and this tests/ directory are).
ROOT = Path(__file__).resolve().parent.parent
#: The planner's command line, run with this interpreter: ``[*SPAR, "plan", ...]``.
SPAR = [sys.executable, "-m", "spar_py"]
