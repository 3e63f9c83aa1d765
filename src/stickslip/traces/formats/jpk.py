"""JPK (Bruker JPK NanoWizard) ``.jpk`` image files through AFMReader (optional extra).

A ``.jpk`` image is a TIFF file: page 0 is a thumbnail holding the scan geometry
(grid lengths in m and pixel counts), every other page one channel, whose JPK tags
give its name (``height``, ``vDeflection``, ``hDeflection`` ...), whether it is the
retrace, and the calibration slots with their units. The images are read with
AFMReader's ``load_jpk`` (scaled to the default slot's units, rows kept in the
stored order); the channel list and the units come from the same JPK tags, read
with tifffile (a dependency of AFMReader), since ``load_jpk`` returns neither.

Lateral channels are those whose name says so (``Lateral ...``, ``Friction`` ...) and
JPK's horizontal deflection ``hDeflection`` (named ``Lateral deflection`` here). Install with
``pip install 'stickslip[jpk]'``; without it, reading a ``.jpk`` file fails with one
line naming the extra.
"""

from __future__ import annotations

import importlib
from pathlib import Path
from typing import Any

import numpy as np

from stickslip.traces.formats.common import (
    RETRACE,
    TRACE,
    Channel,
    ScanFile,
    as_image,
    damage_reason,
    is_lateral_name,
    optional_import,
    quiet_logger,
    read_bytes,
)
from stickslip.traces.trace import TraceReadError

FORMAT = "JPK"
EXTRA = "jpk"
_TIFF_SIGNATURES = (b"II*\x00", b"MM\x00*")
# JPK TIFF tags (JPK image specification, as used by AFMReader and Gwyddion)
TAG_CHANNEL = 0x8050
TAG_RETRACE = 0x8051
TAG_FANCY_NAME = 0x8052
TAG_DEFAULT_SLOT = 0x8081
TAG_N_SLOTS = 0x8080
TAG_SLOT_NAME = 0x8090
TAG_ENCODER_UNIT = 0x80A2
SLOT_STRIDE = 0x30
_LATERAL_JPK_NAMES = {"hdeflection", "lateraldeflection"}


def _tag(page: Any, code: int) -> Any:
    tag = page.tags.get(code)
    return None if tag is None else tag.value


def _unit(page: Any) -> str:
    """Unit of the default calibration slot (``V``, ``N``, ``m`` ...), ``""`` if unstated."""
    default = _tag(page, TAG_DEFAULT_SLOT)
    try:
        n_slots = int(_tag(page, TAG_N_SLOTS) or 0)
    except (TypeError, ValueError):
        return ""
    for i in range(min(n_slots, 64)):
        if _tag(page, TAG_SLOT_NAME + i * SLOT_STRIDE) == default:
            return str(_tag(page, TAG_ENCODER_UNIT + i * SLOT_STRIDE) or "")
    return ""


def _channels(path: Path, tifffile: Any) -> list[tuple[str, str, str, str, tuple[int, int]]]:
    """``(jpk name, display name, direction, unit, shape)`` of every image page."""
    try:
        with tifffile.TiffFile(str(path)) as tif:
            out = []
            for page in list(tif.pages)[1:]:  # page 0 is the thumbnail
                raw = _tag(page, TAG_CHANNEL)
                if raw is None:
                    continue
                fancy = str(_tag(page, TAG_FANCY_NAME) or raw)
                direction = RETRACE if _tag(page, TAG_RETRACE) else TRACE
                shape = (int(page.shape[0]), int(page.shape[1])) if len(page.shape) >= 2 else (0, 0)
                out.append((str(raw), fancy, direction, _unit(page), shape))
            return out
    except Exception as e:  # tifffile raises many types on damaged files
        raise TraceReadError(path, damage_reason(e, path)) from None


def _display_name(raw: str, fancy: str) -> str:
    if is_lateral_name(fancy):
        return fancy
    if raw.lower() in _LATERAL_JPK_NAMES:
        return "Lateral deflection"
    return fancy


def read_jpk(path: Path) -> ScanFile:
    """Read the image channels of a JPK ``.jpk`` file (lateral ones with their data).

    Raises
    ------
    TraceReadError
        One line when the file is not a TIFF-based JPK image, AFMReader is not
        installed (naming the ``jpk`` extra), or a channel cannot be read.
    """
    if read_bytes(path, 4) not in _TIFF_SIGNATURES:
        raise TraceReadError(path, "not a JPK image file (no TIFF signature)")
    jpk = optional_import("AFMReader.jpk", path, extra=EXTRA)
    try:  # AFMReader logs every load to stderr through loguru: keep one-line output
        importlib.import_module("loguru").logger.disable("AFMReader")
    except ImportError:
        pass
    tifffile = optional_import("tifffile", path, extra=EXTRA)
    with quiet_logger("tifffile"):  # its warnings on damaged files
        return _read(path, jpk, tifffile)


def _read(path: Path, jpk: Any, tifffile: Any) -> ScanFile:
    listing = _channels(path, tifffile)
    if not listing:
        raise TraceReadError(path, "no JPK image channels (a force map or spectroscopy file?)")
    scan = ScanFile(path=path, fmt=FORMAT)
    for raw, fancy, direction, unit, shape in listing:
        name = _display_name(raw, fancy)
        data = None
        if is_lateral_name(name):
            try:
                image, px_nm = jpk.load_jpk(path, channel=f"{raw}_{direction}", flip_image=False)
            except Exception as e:  # AFMReader raises KeyError/ValueError on bad tags
                raise TraceReadError(path, f"channel {name} ({direction}): "
                                           f"{damage_reason(e, path)}") from None
            data = as_image(np.asarray(image), path, f"channel {name}")
            shape = data.shape
            if scan.scan_size_nm is None and np.isfinite(px_nm) and px_nm > 0:
                scan.scan_size_nm = float(px_nm) * data.shape[1]
        scan.channels.append(Channel(name, direction, unit, shape, data))
    return scan
