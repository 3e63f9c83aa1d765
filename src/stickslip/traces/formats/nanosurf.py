"""Nanosurf ``.nid`` files through NSFopen.

Images come from ``Scan forward`` (trace) and ``Scan backward`` (retrace) frames,
both stored with columns in increasing x. Units per channel come from the header
(``Dim2Unit``); the scan size from ``ScanRange``, the velocity from the scan range
over ``ScanTime`` (time per line), and the load from the z-feedback ``SetPoint``
(converted to nN when it is a force).
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

from stickslip.traces.formats.common import (
    RETRACE,
    TRACE,
    Channel,
    ScanFile,
    as_image,
    force_scale_to_nN,
    is_lateral_name,
    length_to_nm,
    optional_import,
    read_bytes,
)
from stickslip.traces.trace import TraceReadError

FORMAT = "Nanosurf NID"
_FRAMES = {"Forward": TRACE, "Backward": RETRACE}
_COUNT = re.compile(rb"-Count=(\d+)")
_TYPED = re.compile(r"(\S)\[(.*)\]\*\[(.*)\]")
MAX_COUNT = 10_000


def _check(path: Path) -> None:
    head = read_bytes(path, 1_000_000)
    if not head.startswith(b"[DataSet]"):
        raise TraceReadError(path, "not a Nanosurf NID file (no '[DataSet]' header)")
    # NSFopen loops over these counts: refuse absurd values from damaged headers
    if any(int(c) > MAX_COUNT for c in _COUNT.findall(head)):
        raise TraceReadError(path, "damaged Nanosurf NID header (absurd group count)")


def _units(header: dict[str, Any]) -> dict[tuple[str, str], str]:
    out = {}
    for sec in header.values():
        if isinstance(sec, dict) and "Dim2Name" in sec and "Frame" in sec:
            out[(sec["Frame"], sec["Dim2Name"])] = sec.get("Dim2Unit", "")
    return out


def _typed(header: dict[str, Any], section: str, key: str) -> tuple[list[float], str] | None:
    m = _TYPED.search(str(header.get(section, {}).get(key, "")))
    if not m:
        return None
    try:
        return [float(v) for v in m.group(2).split(",")], m.group(3).split(",")[0]
    except ValueError:
        return None


def read_nid(path: Path) -> ScanFile:
    """Read the image channels and acquisition metadata of a ``.nid`` file."""
    _check(path)
    nsf = optional_import("NSFopen.read", path)
    nid = nsf.nid_read(str(path), dataframe=False)
    header = nid.param["HeaderDump"]
    units = _units(header)
    scan = ScanFile(path=path, fmt=FORMAT)
    images = nid.data.get("Image", {}) if isinstance(nid.data, dict) else {}
    for frame, direction in _FRAMES.items():
        for name, data in images.get(frame, {}).items():
            unit = units.get((f"Scan {frame.lower()}", name), "")
            img = as_image(data, path, f"channel {name}")
            lateral = is_lateral_name(name)
            scan.channels.append(
                Channel(name, direction, unit, img.shape, img if lateral else None)
            )
    imaging = "DataSet\\Parameters\\Imaging"
    rng, time = _typed(header, imaging, "ScanRange"), _typed(header, imaging, "ScanTime")
    if rng and rng[0] and rng[0][0] > 0:
        scan.scan_size_nm = length_to_nm(rng[0][0], rng[1] or "m")
        if time and time[0] and time[0][0] > 0:
            scan.meta["velocity_nm_per_s"] = scan.scan_size_nm / time[0][0]
            scan.meta["scan_rate_hz"] = 1.0 / (2.0 * time[0][0])
    sp = _typed(header, "DataSet\\Parameters\\ZFeedback", "SetPoint")
    if sp and sp[0]:
        f = force_scale_to_nN(sp[1])
        load, unit = (sp[0][0] * f, "nN") if f else (sp[0][0], sp[1])
        scan.meta.update(load=load, load_unit=unit, setpoint=load)
    return scan
