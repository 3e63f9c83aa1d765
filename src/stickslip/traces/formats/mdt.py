"""NT-MDT ``.mdt`` files (Nova / Nova Px), read here from the public format description.

An ``.mdt`` file is a 33-byte header (signature ``01 b0 93 ff``, the size of the
rest, the index of the last frame) followed by frames. Every frame starts with a
22-byte header: its size in bytes (header included), its type, version, date and
time, and the size of its variables block. Little-endian throughout.

Frames read here:

- type 0, scanned data (older Nova): three axis scales (offset, step, unit code),
  the scan variables (ADC channel, velocity in angstrom/s ...), the frame mode
  (``xres``, ``yres``, measured dots), then ``yres * xres`` int16 values
  (``offset + step * raw``), a cp1251 title and a UTF-16 XML comment.
- type 106, MDA ("multi-dimensional array", Nova Px): a header of block sizes, a
  UTF-8 title (``1F:Height`` = pass 1, Forward), a UTF-16 XML comment with the scan
  parameters, then the array description: its dimensions and measurands, each a
  calibration (bias, scale, index range, data type, name and unit strings), and the
  array itself. Two dimensions and one measurand make an image
  (``bias + scale * raw``); one-dimensional spectra and three-dimensional volumes are
  listed but not loaded.
- type 3, text; type 190, spectroscopy curves (a list of named blocks, with an
  ``index.xml`` describing points, axes and measured quantities); types 1 and 201,
  old spectroscopy: listed with what they hold, never loaded.

Images become :class:`~.common.Channel` objects: the title's ``F``/``B`` marks the
direction (``Forward`` trace, ``Backward`` retrace) and the rest is the channel
name, so NT-MDT's lateral-force signal ``LF`` (or ``Lateral Force``) is recognised as
lateral. Lines are kept in the stored order, columns in increasing x. Every frame
is also listed in :attr:`~.common.ScanFile.frames` for ``stickslip inspect``.

This is a reader written for stickslip: maintained Python readers exist
(SciFiReaders), but they pull in a large dependency tree for one format.
"""

from __future__ import annotations

import re
import struct
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from stickslip.traces.formats.common import (
    RETRACE,
    TRACE,
    Axis,
    Channel,
    Frame,
    ScanFile,
    direction_from_name,
    is_lateral_name,
    length_to_nm,
    read_bytes,
)
from stickslip.traces.trace import TraceReadError

FORMAT = "NT-MDT MDT"
MAGIC = b"\x01\xb0\x93\xff"
FILE_HEADER_BYTES = 33
FRAME_HEADER_BYTES = 22
AXIS_SCALES_BYTES = 30
SCAN_VARS_BYTES = 43  # the scan variables read after the axis scales
MAX_MDA_ENTRIES = 64  # dimensions or measurands in one MDA frame
MAX_BLOCKS = 1_000_000  # named blocks in one curves frame

FRAME_KINDS = {
    0: "scanned data",
    1: "spectroscopy",
    3: "text",
    105: "old MDA",
    106: "MDA",
    107: "palette",
    190: "spectroscopy curves",
    201: "curves",
}

# Unit codes of the old frames' axis scales (the public unit table).
UNIT_CODES = {
    -10: "1/cm", -5: "m", -4: "cm", -3: "mm", -2: "µm", -1: "nm", 0: "Å", 1: "nA",
    2: "V", 3: "", 4: "kHz", 5: "deg", 6: "%", 7: "°C", 8: "V", 9: "s", 10: "ms",
    11: "µs", 12: "ns", 13: "", 14: "px", 20: "A", 21: "mA", 22: "µA", 23: "nA",
    24: "pA", 25: "V", 26: "mV", 27: "µV", 28: "nV", 29: "pV", 30: "N", 31: "mN",
    32: "µN", 33: "nN", 34: "pN",
}
# The ADC signal of an old scanned frame (s_mode), for frames without a title.
ADC_SIGNALS = {
    0: "Height", 1: "DFL", 2: "Lateral F", 3: "Bias V", 4: "Current", 5: "FB-Out",
    6: "MAG", 7: "MAG*Sin", 8: "MAG*Cos", 9: "RMS", 10: "CalcMag", 11: "Phase1",
    12: "Phase2", 13: "CalcPhase", 14: "Ex1", 15: "Ex2", 16: "HvX", 17: "HvY",
    18: "Snap Back",
}
ADC_LATERAL = 2
# MDA data type codes -> numpy little-endian dtypes (float48/80 and fixed are not read)
MDA_DTYPES = {
    -1: "i1", 1: "u1", -2: "<i2", 2: "<u2", -4: "<i4", 4: "<u4", -8: "<i8", 8: "<u8",
    -(4 + 23 * 256): "<f4", -(8 + 52 * 256): "<f8",
}
# MDA calibrations may carry only an SI code instead of a unit string.
SI_CODES = {0x1: "", 0x101: "m", 0x100001: "A", 0xFFFD010200: "V", 0x1000001: "s"}

_PASS_DIRECTION = re.compile(r"^\s*(\d*)\s*([FB])\s*:\s*(.*)$")
_XML_VALUE = r"<{key}>\s*([^<]*?)\s*</{key}>"


class _Damaged(Exception):
    """A frame's contents contradict its own sizes (caught and reported per file)."""


class _Cursor:
    """Bounds-checked little-endian reads inside one frame."""

    def __init__(self, buf: bytes, start: int, end: int) -> None:
        self.buf, self.pos, self.end = buf, start, end

    def take(self, n: int) -> int:
        """Advance by ``n`` bytes, returning the old position."""
        if n < 0 or self.pos + n > self.end:
            raise _Damaged(f"a field of {n} bytes runs past the end of the frame")
        p, self.pos = self.pos, self.pos + n
        return p

    def unpack(self, fmt: str) -> tuple[Any, ...]:
        size = struct.calcsize("<" + fmt)
        return struct.unpack_from("<" + fmt, self.buf, self.take(size))

    def one(self, fmt: str) -> Any:
        return self.unpack(fmt)[0]

    def raw(self, n: int) -> bytes:
        p = self.take(n)
        return self.buf[p:p + n]

    def seek(self, pos: int) -> None:
        if not 0 <= pos <= self.end:
            raise _Damaged("an offset points outside the frame")
        self.pos = pos


def _text(raw: bytes, encoding: str = "utf-8") -> str:
    """Decode a title or unit: the given encoding, else cp1251 (older Nova), never fails."""
    for enc in (encoding, "cp1251"):
        try:
            return raw.decode(enc).strip("\x00").strip()
        except UnicodeDecodeError:
            continue
    return raw.decode("latin-1").strip("\x00").strip()


def _unit(text: str) -> str:
    """Normalise a unit string: Greek mu to micro sign, ``um`` kept as is."""
    return text.replace("\u03bc", "\u00b5").strip()


def _utf16(raw: bytes) -> str:
    return raw.decode("utf-16-le", errors="replace").lstrip("\ufeff")


def _xml_value(xml: str, key: str) -> str | None:
    m = re.search(_XML_VALUE.format(key=re.escape(key)), xml)
    return m.group(1) if m else None


def _channel_name(title: str, index: int) -> tuple[str, str]:
    """``(name, direction)`` from an NT-MDT title such as ``1F:LF`` or ``Height (Backward)``."""
    m = _PASS_DIRECTION.match(title)
    if m and m.group(3).strip():
        return m.group(3).strip(), TRACE if m.group(2) == "F" else RETRACE
    return (title or f"frame {index}"), direction_from_name(title)


def _size_nm(size: float, unit: str) -> float | None:
    try:
        return length_to_nm(size, unit) if size > 0 else None
    except ValueError:
        return None


@dataclass
class _Image:
    """A 2-D frame turned into a channel, with what the scan-level metadata needs."""

    channel: Channel
    size_nm: float | None
    velocity_nm_per_s: float | None


# ----------------------------------------------------------------------------- frames


def _scan_vars_frame(buf: bytes, start: int, size: int, var_size: int, index: int,
                     type_code: int, all_data: bool) -> tuple[Frame, _Image | None]:
    """Old scanned-data frame (type 0) and the old spectroscopy frames (1, 201)."""
    kind = FRAME_KINDS[type_code]
    if var_size < AXIS_SCALES_BYTES + SCAN_VARS_BYTES:
        raise _Damaged(f"variables block of {var_size} bytes is too short")
    c = _Cursor(buf, start + FRAME_HEADER_BYTES, start + size)
    scales = [c.unpack("ffh") for _ in range(3)]  # (offset, step, unit code) for x, y, z
    adc = c.one("B")
    c.take(1 + 2 + 2 + 2 + 4 + 2 + 1 + 1 + 1 + 1 + 1 + 1)  # mode ... power_of_2
    velocity_a_per_s = c.one("f")
    c.seek(start + FRAME_HEADER_BYTES + var_size)
    _mode, xres, yres, ndots = c.unpack("HHHH")
    if ndots:
        c.take(14 + 16 * ndots)
    data_pos = c.take(2 * xres * yres)
    title = ""  # optional; the UTF-16 XML comment after it is not needed
    if c.end - c.pos >= 4:
        n = c.one("I")
        if n <= c.end - c.pos:
            title = _text(c.raw(n), "cp1251")
    (_, x_step, x_code), (_, y_step, y_code), (z_off, z_step, z_code) = scales
    x_unit, y_unit = UNIT_CODES.get(x_code, ""), UNIT_CODES.get(y_code, "")
    z_unit = UNIT_CODES.get(z_code, "")
    if type_code != 0:
        frame = Frame(index, type_code, kind, title, (yres, xres) if yres > 1 else (xres,),
                      z_unit, [Axis("x", x_unit, xres, abs(x_step))], "listed, not read")
        return frame, None
    name = title or ADC_SIGNALS.get(adc, f"frame {index}")
    if adc == ADC_LATERAL and not is_lateral_name(name):
        name = f"Lateral F {name}"
    name, direction = _channel_name(name, index)
    axes = [Axis("x", x_unit, xres, abs(x_step)), Axis("y", y_unit, yres, abs(y_step))]
    frame = Frame(index, type_code, kind, title, (yres, xres), z_unit, axes)
    if xres * yres == 0:
        frame.note = "empty"
        return frame, None
    raw = np.frombuffer(buf, dtype="<i2", count=xres * yres, offset=data_pos)
    img = (z_off + z_step * raw.astype(float)).reshape(yres, xres)
    keep = all_data or is_lateral_name(name)
    ch = Channel(name, direction, z_unit, img.shape, img if keep else None)
    velocity = velocity_a_per_s * 0.1 if velocity_a_per_s > 0 else None
    return frame, _Image(ch, _size_nm(xres * abs(x_step), x_unit), velocity)


@dataclass
class _Calibration:
    name: str
    unit: str
    bias: float
    scale: float
    count: int
    dtype: int


def _calibration(c: _Cursor) -> _Calibration:
    start = c.pos
    total, struct_len = c.unpack("II")
    body = c.pos
    n_name, n_comment, n_unit = c.unpack("III")
    si_code, _accuracy, _function = c.unpack("QdQ")
    bias, scale = c.unpack("dd")
    lo, hi = c.unpack("QQ")
    dtype, n_author = c.unpack("iI")
    c.seek(body + struct_len)
    name = _text(c.raw(n_name))
    c.raw(n_comment)
    unit = _unit(_text(c.raw(n_unit))) if n_unit else SI_CODES.get(si_code, "")
    c.raw(n_author)
    if total < 8:
        raise _Damaged(f"calibration record of {total} bytes")
    c.seek(start + total)
    count = hi - lo + 1 if hi >= lo and hi != 2**64 - 1 else 0
    return _Calibration(name, unit, bias, scale, count, dtype)


def _mda_frame(buf: bytes, start: int, size: int, index: int, all_data: bool,
               ) -> tuple[Frame, _Image | None, str]:
    """MDA frame (type 106): the frame listing, the image channel if 2-D, the XML comment."""
    c = _Cursor(buf, start + FRAME_HEADER_BYTES, start + size)
    record = c.pos
    head_size, _total = c.unpack("II")
    c.take(16 * 2 + 4)  # two GUIDs and the frame status
    n_name, n_xml, n_view, n_spec, n_source, _n_var, _data_offset, _data_size = \
        c.unpack("IIIIIIII")
    c.seek(record + head_size)
    title = _text(c.raw(n_name))
    xml = _utf16(c.raw(n_xml))
    c.take(n_spec + n_view + n_source)
    c.take(4)  # size of what follows
    struct_len = c.one("I")
    struct_pos = c.pos
    array_size, cell_size, n_dims, n_meas = c.unpack("QIII")
    if n_dims > MAX_MDA_ENTRIES or n_meas > MAX_MDA_ENTRIES:
        raise _Damaged(f"{n_dims} dimensions and {n_meas} measurands")
    c.seek(struct_pos + struct_len)
    dims = [_calibration(c) for _ in range(n_dims)]
    meas = [_calibration(c) for _ in range(n_meas)]
    names = "xyz"
    axes = [Axis(names[i] if i < 3 else f"d{i}", d.unit, d.count, abs(d.scale))
            for i, d in enumerate(dims)]
    unit = meas[0].unit if meas else ""
    if n_dims == 2 and n_meas == 1:
        frame = Frame(index, 106, "MDA image", title, (dims[1].count, dims[0].count), unit, axes)
        return frame, _mda_image(buf, c, frame, dims, meas[0], all_data), xml
    if (n_dims, n_meas) in ((1, 1), (0, 2)):
        n = dims[0].count if dims else array_size
        frame = Frame(index, 106, "MDA spectrum", title, (n,), unit, axes, "listed, not read")
    elif n_dims == 3:
        shape = (dims[2].count, dims[1].count, dims[0].count)
        frame = Frame(index, 106, "MDA volume", title, shape, unit, axes,
                      f"{n_meas} measurand(s); listed, not read")
    else:
        frame = Frame(index, 106, "MDA", title, (), unit, axes,
                      f"{n_dims} dimensions, {n_meas} measurands "
                      f"({array_size} cells of {cell_size} bytes); listed, not read")
    return frame, None, xml


def _mda_image(buf: bytes, c: _Cursor, frame: Frame, dims: list[_Calibration],
               z: _Calibration, all_data: bool) -> _Image | None:
    nx, ny = dims[0].count, dims[1].count
    if nx <= 0 or ny <= 0:
        raise _Damaged(f"image of {ny} x {nx} points")
    dtype = MDA_DTYPES.get(z.dtype)
    if dtype is None:
        frame.note = f"data type {z.dtype} not supported; not read"
        return None
    item = np.dtype(dtype).itemsize
    pos = c.take(nx * ny * item)
    raw = np.frombuffer(buf, dtype=dtype, count=nx * ny, offset=pos)
    with np.errstate(invalid="ignore", over="ignore"):  # damaged cells: NaN, refused later
        img = (z.bias + z.scale * raw.astype(float)).reshape(ny, nx)
    name, direction = _channel_name(frame.title, frame.index)
    keep = all_data or is_lateral_name(name)
    ch = Channel(name, direction, z.unit, img.shape, img if keep else None)
    return _Image(ch, _size_nm(nx * abs(dims[0].scale), dims[0].unit), None)


def _text_frame(buf: bytes, start: int, size: int, index: int) -> Frame:
    """Text frame (type 3): text length, 14 reserved bytes, text, title, XML comment."""
    frame = Frame(index, 3, FRAME_KINDS[3])
    try:
        c = _Cursor(buf, start + FRAME_HEADER_BYTES, start + size)
        n_text = c.one("I")
        c.take(14)
        text = _text(c.raw(n_text))
        n_title = c.one("I")
        frame.title = _text(c.raw(n_title))
    except _Damaged:
        frame.note = "text not decoded"
        return frame
    shown = " ".join(text.split())
    frame.note = f"{len(text)} characters" + (f": '{shown[:60]}'" if shown else "")
    return frame


_ATTRS = re.compile(r'(\w+)="([^"]*)"')


def _elements(xml: str, tag: str) -> list[dict[str, str]]:
    return [dict(_ATTRS.findall(m.group(1))) for m in re.finditer(rf"<{tag}\b([^>]*)>", xml)]


def _curves_frame(buf: bytes, start: int, size: int, index: int) -> Frame:
    """Spectroscopy curves (type 190), only listed: a damaged one is noted, not fatal."""
    try:
        return _curves_listing(buf, start, size, index)
    except _Damaged as e:
        return Frame(index, 190, FRAME_KINDS[190], note=f"damaged ({e}); not read")


def _curves_listing(buf: bytes, start: int, size: int, index: int) -> Frame:
    """Spectroscopy curves (type 190): named blocks; ``index.xml`` says what they hold."""
    frame = Frame(index, 190, FRAME_KINDS[190])
    c = _Cursor(buf, start + FRAME_HEADER_BYTES, start + size)
    n_blocks = c.one("I")
    if n_blocks > MAX_BLOCKS or 8 * n_blocks > c.end - c.pos:
        raise _Damaged(f"{n_blocks} blocks")
    lengths = [c.unpack("II") for _ in range(n_blocks)]
    names = [_text(c.raw(n)) for n, _ in lengths]
    blocks = {}
    for name, (_, n) in zip(names, lengths, strict=True):
        blocks.setdefault(name, c.take(n))
    if "index.xml" not in blocks:
        frame.note = f"{n_blocks} blocks; listed, not read"
        return frame
    pos = blocks["index.xml"]
    n = lengths[names.index("index.xml")][1]
    xml = buf[pos:pos + n].decode("utf-8", errors="replace")
    quantities = _elements(xml, "Name")
    axes_xml, meas, points = _elements(xml, "Axis"), _elements(xml, "Meas"), _elements(xml, "Point")

    def quantity(ref: str) -> dict[str, str]:
        i = int(ref) if ref.lstrip("-").isdigit() else -1
        return quantities[i] if 0 <= i < len(quantities) else {}

    axes = []
    for a in axes_xml:
        q = quantity(a.get("name", ""))
        count = int(a["count"]) if a.get("count", "").isdigit() else 0
        try:
            span = abs(float(a.get("stop", "nan")) - float(a.get("start", "nan")))
            step = span / (count - 1) if count > 1 else None
        except ValueError:
            step = None
        axes.append(Axis(q.get("name", "axis"), q.get("unit", ""), count, step))
    measured = sorted({quantity(m.get("name", "")).get("name", "?") for m in meas})
    units = sorted({quantity(m.get("name", "")).get("unit", "") for m in meas})
    frame.unit = "/".join(u for u in units if u)
    if axes and meas:
        frame.shape = (len(meas), axes[0].size)
    frame.axes = axes
    frame.note = (f"{len(points)} points, {len(meas)} curves of {', '.join(measured) or '?'}; "
                  "listed, not read")
    return frame


# ----------------------------------------------------------------------------- file


def _frame_bounds(buf: bytes, path: Path) -> list[tuple[int, int, int, int]]:
    """``(start, size, type, var_size)`` of every frame, checking the sizes chain up."""
    if len(buf) < FILE_HEADER_BYTES or not buf.startswith(MAGIC):
        raise TraceReadError(path, "not an NT-MDT file (no MDT signature)")
    declared, = struct.unpack_from("<I", buf, 4)
    last, = struct.unpack_from("<H", buf, 12)
    end = FILE_HEADER_BYTES + declared
    if end > len(buf):
        raise TraceReadError(path, f"truncated NT-MDT file ({len(buf)} bytes; "
                                   f"the header says {end})")
    out = []
    pos = FILE_HEADER_BYTES
    for i in range(last + 1):
        if pos + FRAME_HEADER_BYTES > end:
            raise TraceReadError(path, f"damaged NT-MDT file: frame {i} of {last + 1} "
                                       "starts past the end of the data")
        size, type_code = struct.unpack_from("<IH", buf, pos)
        var_size, = struct.unpack_from("<H", buf, pos + 20)
        if size < FRAME_HEADER_BYTES or pos + size > end:
            raise TraceReadError(path, f"damaged NT-MDT file: frame {i} declares {size} bytes, "
                                       f"{end - pos} remain")
        out.append((pos, size, type_code, var_size))
        pos += size
    return out


def _velocity_from_xml(xml: str) -> float | None:
    """Tip velocity in nm/s from the MDA comment's ``scshRate`` (unit ``scshRateUnits``)."""
    rate, unit = _xml_value(xml, "scshRate"), _xml_value(xml, "scshRateUnits")
    if rate is None or not unit or "/s" not in unit:
        return None
    try:
        v = float(rate) * length_to_nm(1.0, unit.split("/")[0])
    except ValueError:
        return None
    return v if v > 0 else None


def read_mdt(path: Path, all_data: bool = False) -> ScanFile:
    """Read every frame of an NT-MDT ``.mdt`` file.

    Parameters
    ----------
    path : Path
        The file.
    all_data : bool
        Keep the data of every image channel, not only of the lateral-force ones.

    Returns
    -------
    ScanFile
        ``channels``: one per 2-D image frame (data kept for lateral-force
        channels, or all with ``all_data``); ``frames``: every frame with its type,
        axes, unit and shape; ``scan_size_nm`` and ``velocity_nm_per_s`` from the first
        image (lateral ones first) when stated.

    Raises
    ------
    TraceReadError
        One line when the file is not an MDT file, is truncated, or a data frame
        contradicts its own sizes.
    """
    buf = read_bytes(path)
    scan = ScanFile(path=path, fmt=FORMAT)
    images: list[_Image] = []
    velocity = None
    for index, (start, size, type_code, var_size) in enumerate(_frame_bounds(buf, path)):
        kind = FRAME_KINDS.get(type_code, "unknown")
        try:
            if type_code in (0, 1, 201):
                frame, image = _scan_vars_frame(buf, start, size, var_size, index, type_code,
                                                all_data)
            elif type_code == 106:
                frame, image, xml = _mda_frame(buf, start, size, index, all_data)
                velocity = velocity or _velocity_from_xml(xml)
            elif type_code == 3:
                frame, image = _text_frame(buf, start, size, index), None
            elif type_code == 190:
                frame, image = _curves_frame(buf, start, size, index), None
            else:
                frame, image = Frame(index, type_code, kind, note="not read"), None
        except _Damaged as e:
            raise TraceReadError(path, f"damaged NT-MDT frame {index} "
                                       f"(type {type_code}, {kind}): {e}") from None
        scan.frames.append(frame)
        if image is not None:
            images.append(image)
            scan.channels.append(image.channel)
    if images:
        first = sorted(images, key=lambda im: not im.channel.is_lateral)[0]
        scan.scan_size_nm = first.size_nm
        velocity = first.velocity_nm_per_s or velocity
    if velocity:
        scan.meta["velocity_nm_per_s"] = velocity
        if scan.scan_size_nm:
            scan.meta["scan_rate_hz"] = velocity / (2.0 * scan.scan_size_nm)
    return scan
