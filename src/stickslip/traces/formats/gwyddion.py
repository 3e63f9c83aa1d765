"""Gwyddion ``.gwy`` files through gwyfile (also the export route for NT-MDT ``.mdt``).

Each data field is a channel; its title gives the name and the direction
(``Forward``/``Trace`` or ``Backward``/``Retrace``, as Gwyddion's importers and
users name them), ``si_unit_z`` the unit and ``xreal`` (in ``si_unit_xy``) the scan
size. Gwyddion stores the rows top to bottom, columns in increasing x.
"""

from __future__ import annotations

from pathlib import Path
from types import ModuleType
from typing import Any

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


def _guard_parser(gwyfile: ModuleType) -> None:
    """Make gwyfile's component parser refuse a corrupt component.

    gwyfile walks an object's components in a ``while`` loop that advances by each
    component's size; a corrupt file (a damaged type code or NUL) gives a size of 0 or
    beyond the buffer, and the loop never ends. Wrapping the parser once turns that
    into an error that :func:`read_gwy`'s caller reports as one line.
    """
    objects = gwyfile.objects
    parse = objects.component_from_buffer
    if getattr(parse, "stickslip_guarded", False):
        return

    def guarded(buf: bytes, return_size: bool = False) -> Any:
        out = parse(buf, return_size=return_size)
        if return_size and not 0 < out[-1] <= len(buf):
            raise ValueError("corrupt Gwyddion component (size out of range)")
        return out

    guarded.stickslip_guarded = True  # type: ignore[attr-defined]
    objects.component_from_buffer = guarded


def read_gwy(path: Path) -> ScanFile:
    """Read every data field of a ``.gwy`` container."""
    if read_bytes(path, 4) != b"GWYP":
        raise TraceReadError(path, "not a Gwyddion file (no 'GWYP' signature)")
    gwyfile = optional_import("gwyfile", path)
    _guard_parser(gwyfile)
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
