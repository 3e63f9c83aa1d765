"""Asylum Research (Oxford Instruments) ``.ibw`` images through igor2.

An Asylum image is one Igor wave of shape ``(pixels, lines, channels)`` whose third
dimension labels name the channels (``LateralTrace``, ``LateralRetrace``...). The
wave note holds ``key: value`` lines: ``ScanSize`` (m), ``ScanRate`` (Hz) and the
feedback ``SetPoint`` (V; the deflection setpoint in contact mode). Lateral channels are in volts.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from stickslip.traces.formats.common import (
    Channel,
    ScanFile,
    direction_from_name,
    is_lateral_name,
    optional_import,
    quiet_logger,
    read_bytes,
)
from stickslip.traces.trace import TraceReadError

FORMAT = "Asylum Igor wave"


def _note(raw: Any) -> dict[str, str]:
    text = raw.decode("latin1") if isinstance(raw, bytes) else str(raw or "")
    out = {}
    for line in text.replace("\r", "\n").split("\n"):
        key, sep, value = line.partition(":")
        if sep:
            out[key.strip()] = value.strip()
    return out


def _labels(wave: dict[str, Any], n: int) -> list[str]:
    try:
        raw = wave["labels"][2]
    except (KeyError, IndexError, TypeError):
        raw = []
    names = [x.decode("latin1") if isinstance(x, bytes) else str(x) for x in raw][1:]
    return [names[i] if i < len(names) and names[i] else f"channel{i}" for i in range(n)]


def _num(note: dict[str, str], key: str) -> float | None:
    try:
        v = float(note[key])
    except (KeyError, ValueError):
        return None
    return v if np.isfinite(v) else None


def read_ibw(path: Path) -> ScanFile:
    """Read the image layers and note of an Asylum ``.ibw`` file."""
    head = read_bytes(path, 2)
    if len(head) < 2 or not ({head[0], head[1]} & {1, 2, 3, 5}):
        raise TraceReadError(path, "not an Igor binary wave (bad version field)")
    binarywave = optional_import("igor2.binarywave", path)
    with quiet_logger("igor2.binarywave"):  # it logs damaged waves before raising
        wave = binarywave.load(str(path))["wave"]
    data = np.asarray(wave["wData"])
    if data.ndim == 2:
        data = data[:, :, None]
    if data.ndim != 3 or data.dtype.kind not in "fiu" or min(data.shape) < 1:
        raise TraceReadError(path, f"not an image wave (shape {data.shape})")
    note = _note(wave.get("note", b""))
    scan = ScanFile(path=path, fmt=FORMAT)
    for i, name in enumerate(_labels(wave, data.shape[2])):
        img = np.asarray(data[:, :, i], dtype=float).T  # rows = lines, columns = x
        lateral = is_lateral_name(name)
        unit = "V" if lateral else ""
        scan.channels.append(
            Channel(name, direction_from_name(name), unit, img.shape, img if lateral else None)
        )
    size = _num(note, "ScanSize")
    if size and size > 0:
        scan.scan_size_nm = size * 1e9
    rate = _num(note, "ScanRate")
    if rate and rate > 0:
        scan.meta["scan_rate_hz"] = rate
        if scan.scan_size_nm:
            scan.meta["velocity_nm_per_s"] = 2.0 * scan.scan_size_nm * rate
    setpoint = _num(note, "SetPoint")
    if setpoint is not None:
        scan.meta.update(load=setpoint, load_unit="V", setpoint=setpoint)
    return scan
