"""Bruker / Veeco NanoScope files (``.spm``, ``.000``...) through pySPM.

pySPM decodes the image data and scales it to the channel's unit (volts for
Friction). Before handing a file to pySPM the header is checked, because pySPM
reads header lines until ``*File list end`` and would loop forever on a file
without it, and the image blocks are checked against the file size.

Metadata read from the header: scan size (per image), scan rate (Hz), tip velocity
``2 * scan size * scan rate`` (trace plus retrace per line period), and in contact
mode the deflection setpoint ``@2:AFMSetDeflection`` as the load (in V).
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

from stickslip.traces.formats.common import (
    MAX_HEADER_BYTES,
    RETRACE,
    TRACE,
    Channel,
    ScanFile,
    as_image,
    is_lateral_name,
    length_to_nm,
    optional_import,
    read_bytes,
)
from stickslip.traces.trace import TraceReadError

FORMAT = "Bruker NanoScope"
_END = b"*File list end"
_NAME = re.compile(rb'"([^"]*)"')
_VALUE = re.compile(r"\)\s*(-?[0-9.]+(?:[eE][-+]?\d+)?)\s*(\S*)\s*$")


def _check_header(path: Path) -> None:
    head = read_bytes(path, MAX_HEADER_BYTES)
    if not head.startswith((b"\\*File list", b"\\*Force file list", b"\\*EC File list")):
        raise TraceReadError(path, "not a Bruker NanoScope file (no '\\*File list' header)")
    # pySPM stops at the first line equal to '*File list end' once backslashes are removed
    if not any(line.rstrip().replace(b"\\", b"") == _END for line in head.split(b"\n")):
        raise TraceReadError(path, "truncated or damaged Bruker header (no '*File list end')")


def _text(d: dict, key: str) -> str | None:
    val = d.get(key.encode())
    if not val:
        return None
    return b": ".join(val).decode("latin1").strip()


def _float(d: dict, key: str) -> float | None:
    txt = _text(d, key)
    try:
        return float(txt.split()[0]) if txt else None
    except ValueError:
        return None


def _layer_channel(layer: dict, size: int, path: Path) -> Channel | None:
    tag = layer.get(b"@2:Image Data")
    if not tag:
        return None
    m = _NAME.search(b": ".join(tag))
    name = m.group(1).decode("latin1") if m else b": ".join(tag).decode("latin1")
    direction = RETRACE if (_text(layer, "Line Direction") or "") == "Retrace" else TRACE
    try:
        lines = int(_text(layer, "Number of lines") or "")
        pixels = int(_text(layer, "Samps/line") or "")
        offset = int(_text(layer, "Data offset") or "")
        length = int(_text(layer, "Data length") or "")
    except ValueError:
        raise TraceReadError(path, f"channel {name}: missing or bad image size in header") from None
    if lines < 1 or pixels < 1 or offset < 0 or length < lines * pixels:
        raise TraceReadError(path, f"channel {name}: bad image size in header")
    if offset + length > size:
        raise TraceReadError(path, f"truncated: image data of channel {name} ends past the file")
    return Channel(name=name, direction=direction, unit="", shape=(lines, pixels))


def _scan_size_nm(layer: dict) -> float | None:
    parts = (_text(layer, "Scan Size") or "").split()
    try:
        return length_to_nm(float(parts[0]), parts[2]) if len(parts) >= 3 else None
    except ValueError:
        return None


def _setpoint(scanner: dict) -> tuple[float | None, str | None]:
    mode = _text(scanner, "@MicroscopeList") or ""
    raw = _text(scanner, "@2:AFMSetDeflection")
    if raw is None or ("Contact" not in mode and mode):
        return None, None
    m = _VALUE.search(raw)
    return (float(m.group(1)), m.group(2) or "V") if m else (None, None)


def read_bruker(path: Path) -> ScanFile:
    """Read a NanoScope file: lateral channels with data, the others listed only.

    Raises
    ------
    TraceReadError
        If the file is not a NanoScope file, is truncated, or pySPM is missing.
    """
    _check_header(path)
    pyspm = optional_import("pySPM", path)
    bruker = pyspm.Bruker(str(path))
    size = path.stat().st_size
    scan = ScanFile(path=path, fmt=FORMAT)
    scanner: dict[bytes, Any] = bruker.scanners[0] if bruker.scanners else {}
    for layer in bruker.layers:
        ch = _layer_channel(layer, size, path)
        if ch is None:
            continue
        scan.scan_size_nm = scan.scan_size_nm or _scan_size_nm(layer)
        lateral = is_lateral_name(ch.name)
        try:  # mock_data: pySPM works out the unit without reading the image
            img = bruker.get_channel(
                ch.name, backward=ch.direction == RETRACE, lazy=False, mock_data=not lateral
            )
        except Exception:
            if lateral:
                raise
            img = None  # a non-lateral channel pySPM cannot scale is only listed
        if img is not None:
            ch.unit = str(img.zscale)
        if lateral and img is not None:
            ch.data = as_image(img.pixels, path, f"channel {ch.name}")
        scan.channels.append(ch)
    rate = _float(scanner, "Scan Rate")
    if rate and rate > 0:
        scan.meta["scan_rate_hz"] = rate
        if scan.scan_size_nm:
            scan.meta["velocity_nm_per_s"] = 2.0 * scan.scan_size_nm * rate
    load, unit = _setpoint(scanner)
    if load is not None:
        scan.meta["load"], scan.meta["load_unit"] = load, unit
        scan.meta["setpoint"] = load
    scan.meta["frame_direction"] = next(
        (_text(layer, "Frame direction") for layer in bruker.layers if layer), None
    )
    return scan
