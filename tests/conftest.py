"""Tests run the compiled kernels as the source stands.

numba's on-disk cache (``cache=True``) is keyed on each kernel's own file only: a kernel
that calls kernels of another file is compiled with them inlined, and is not recompiled
when only that other file changes (a changed ``robust.median`` would leave the slip
detector running the old one). Before the session, every cache older than the newest
source file that defines kernels is dropped.
"""

from __future__ import annotations

from pathlib import Path

import stickslip


def _drop_stale_numba_caches(package: Path) -> int:
    kernels = [p for p in package.rglob("*.py") if "@njit" in p.read_text(encoding="utf-8")]
    if not kernels:
        return 0
    newest = max(p.stat().st_mtime for p in kernels)
    dropped = 0
    for cache in [*package.rglob("*.nbi"), *package.rglob("*.nbc")]:
        try:
            if cache.stat().st_mtime < newest:
                cache.unlink()
                dropped += 1
        except FileNotFoundError:  # another process dropped it first
            pass
    return dropped


def pytest_sessionstart(session) -> None:  # noqa: ARG001 (pytest's hook signature)
    _drop_stale_numba_caches(Path(stickslip.__file__).parent)
