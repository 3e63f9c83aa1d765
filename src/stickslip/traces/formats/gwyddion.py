"""Gwyddion ``.gwy`` files through gwyfile (also the export route for NT-MDT ``.mdt``).

Each data field is a channel; its title gives the name and the direction
(``Forward``/``Trace`` or ``Backward``/``Retrace``, as Gwyddion's importers and
users name them), ``si_unit_z`` the unit and ``xreal`` (in ``si_unit_xy``) the scan
size. Gwyddion stores the rows top to bottom, columns in increasing x.
"""

from __future__ import annotations

from pathlib import Path

from stickslip.traces.formats.common import (
    Channel,
    ScanFile,
    as_image,
    direction_from_name,
    is_lateral_name,
    length_to_nm,
    optional_import,
    read_bytes,
)
from stickslip.traces.trace import TraceReadError

FORMAT = "Gwyddion"


def _unit(obj: object) -> str:
    return str(getattr(obj, "unitstr", "") or "") if obj is not None else ""


def read_gwy(path: Path) -> ScanFile:
    """Read every data field of a ``.gwy`` container."""
    if read_bytes(path, 4) != b"GWYP":
        raise TraceReadError(path, "not a Gwyddion file (no 'GWYP' signature)")
    gwyfile = optional_import("gwyfile", path)
    container = gwyfile.load(str(path))
    fields = gwyfile.util.get_datafields(container)
    scan = ScanFile(path=path, fmt=FORMAT)
    for title, field in fields.items():
        name = str(title)
        img = as_image(field.data, path, f"channel {name}")
        lateral = is_lateral_name(name)
        scan.channels.append(
            Channel(name, direction_from_name(name), _unit(field.si_unit_z), img.shape,
                    img if lateral else None)
        )
        if scan.scan_size_nm is None and lateral:
            try:
                scan.scan_size_nm = length_to_nm(field.xreal, _unit(field.si_unit_xy) or "m")
            except (ValueError, KeyError):
                pass
    return scan
