"""Vendor and plain file formats: readers that turn files into per-line traces.

One small module per format (:mod:`.bruker`, :mod:`.nanosurf`, :mod:`.asylum`,
:mod:`.gwyddion`, :mod:`.mdt`, :mod:`.jpk`, :mod:`.text`, :mod:`.hdf5`); :mod:`.maps`
turns friction maps into traces, computes friction loops and groups lines by load. The
registry that maps file suffixes to readers is :mod:`stickslip.traces.readers`. See
docs/reference/formats.md.
"""

from stickslip.traces.formats.common import Channel, ScanFile
from stickslip.traces.formats.maps import (
    assign_loads,
    friction_loop,
    group_by_load,
    map_to_traces,
    reader_options,
    summarise_by_load,
)

__all__ = [
    "Channel",
    "ScanFile",
    "assign_loads",
    "friction_loop",
    "group_by_load",
    "map_to_traces",
    "reader_options",
    "summarise_by_load",
]
