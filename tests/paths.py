"""Where the tests' files are, whatever the working directory pytest runs from."""

from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CONFIGS = ROOT / "configs"
REAL = ROOT.parent / "shared" / "data" / "real"  # the real sensor files (../shared/data/real)
