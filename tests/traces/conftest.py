"""Fixtures for reader tests: the real data beside the project (../shared/data)."""

from __future__ import annotations

from pathlib import Path

import pytest

SHARED_DATA = Path(__file__).resolve().parents[2].parent / "shared" / "data"
RAMP = SHARED_DATA / "bruker-friction-ramp"


@pytest.fixture
def ramp_dir() -> Path:
    """The real Bruker friction-versus-load ramp; skips when shared/ is absent."""
    if not RAMP.is_dir():
        pytest.skip(f"real data folder missing: {RAMP} (clone shared/ beside the project)")
    return RAMP
