"""Signed-distance-field glyphs in MapLibre's glyph protobuf, made from a TrueType font.

MapLibre asks for ``{fontstack}/{start}-{end}.pbf``, 256 code points at a time, and draws text from signed
distance fields: each glyph is a 24 px em bitmap with a 3 px border where a byte is 255 - 255 * (d / 8 + 0.25)
for a distance d in pixels from the outline (positive outside), so the outline sits at 191. The glyphs are
rendered with Pillow at 4x and the distances come from scipy's exact Euclidean distance transform, then
averaged down to the 24 px grid.

The protobuf (``glyphs`` > ``fontstack`` > ``glyph``) has seven scalar fields; it is written here with a
few lines of wire format rather than a generated module.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from numpy.typing import NDArray
from PIL import Image, ImageDraw, ImageFont
from scipy import ndimage

from engine.errors import InvalidParameter

#: The em size MapLibre lays glyphs out at, pixels.
GLYPH_SIZE_PX = 24
#: Empty pixels around every glyph bitmap (MapLibre's GLYPH_PBF_BORDER).
BORDER_PX = 3
#: Distance, in pixels, over which the field runs from the outline to 0 or 255.
SDF_RADIUS_PX = 8.0
#: Share of the byte range outside the outline (the outline is at 255 * (1 - cutoff)).
SDF_CUTOFF = 0.25
#: Rendering is done this many times finer, for sub-pixel outlines.
OVERSAMPLE = 4
#: MapLibre places a glyph's top ``top`` pixels below this line of its 24 px layout box (the same offset
#: MapLibre gives the glyphs it draws locally).
TOP_ORIGIN_PX = 27
#: Code points per glyph range file.
RANGE_SIZE = 256
#: The highest code point MapLibre asks for (the Basic Multilingual Plane).
MAX_CODEPOINT = 65535


@dataclass(frozen=True)
class Glyph:
    """One glyph: its SDF bitmap and metrics in 24 px em pixels.

    Attributes
    ----------
    codepoint
        Unicode code point.
    bitmap
        (height + 6, width + 6) uint8 signed distance field; empty when the glyph draws nothing (a space).
    width, height
        Ink box, pixels.
    left, top
        Ink box offset from the pen position (left) and from MapLibre's top line (top, see TOP_ORIGIN_PX).
    advance
        Pen advance, pixels.
    """

    codepoint: int
    bitmap: NDArray[np.uint8]
    width: int
    height: int
    left: int
    top: int
    advance: int


def check_range(start: int, end: int) -> None:
    """Raise InvalidParameter unless ``start-end`` is one of MapLibre's 256-code-point ranges.

    >>> check_range(0, 255)
    >>> check_range(0, 10)
    Traceback (most recent call last):
    ...
    engine.errors.InvalidParameter: glyph range 0-10: must be N*256-(N*256+255) within 0-65535
    """
    if start % RANGE_SIZE or end != start + RANGE_SIZE - 1 or not 0 <= start <= MAX_CODEPOINT - RANGE_SIZE + 1:
        raise InvalidParameter(f"glyph range {start}-{end}: must be N*256-(N*256+255) within 0-{MAX_CODEPOINT}")


def render_glyph(font: ImageFont.FreeTypeFont, codepoint: int) -> Glyph | None:
    """The SDF glyph of a code point, or None when the font has no glyph for it.

    ``font`` must be loaded at GLYPH_SIZE_PX * OVERSAMPLE.
    """
    char = chr(codepoint)
    if not _has_glyph(font, codepoint):
        return None
    s = OVERSAMPLE
    advance = round(font.getlength(char) / s)
    left_hi, top_hi, right_hi, bottom_hi = font.getbbox(char, anchor="ls")
    if right_hi <= left_hi or bottom_hi <= top_hi:  # nothing drawn: a space
        return Glyph(codepoint, np.zeros((0, 0), np.uint8), 0, 0, 0, 0, advance)
    left = math.floor(left_hi / s)
    ascent = math.ceil(-top_hi / s)
    width = math.ceil(right_hi / s) - left
    height = ascent + math.ceil(bottom_hi / s)
    box_w, box_h = width + 2 * BORDER_PX, height + 2 * BORDER_PX
    image = Image.new("L", (box_w * s, box_h * s), 0)
    origin = ((BORDER_PX - left) * s, (BORDER_PX + ascent) * s)
    ImageDraw.Draw(image).text(origin, char, font=font, fill=255, anchor="ls")
    inside = np.asarray(image) >= 128
    # Distance to the outline, signed: positive outside, in fine pixels.
    signed = ndimage.distance_transform_edt(~inside) - ndimage.distance_transform_edt(inside)
    coarse = signed.reshape(box_h, s, box_w, s).mean(axis=(1, 3)) / s
    field = 255.0 - 255.0 * (coarse / SDF_RADIUS_PX + SDF_CUTOFF)
    bitmap = np.clip(np.rint(field), 0, 255).astype(np.uint8)
    return Glyph(codepoint, bitmap, width, height, left, ascent - TOP_ORIGIN_PX, advance)


def _has_glyph(font: ImageFont.FreeTypeFont, codepoint: int) -> bool:
    # Control characters and code points the font lacks map to its "notdef" box: leave them out, so MapLibre
    # skips them instead of drawing boxes.
    if codepoint < 32 or 127 <= codepoint < 160:
        return False
    path = font.path
    return isinstance(path, str) and codepoint in _cmap(path)


@lru_cache(maxsize=4)
def _cmap(font_path: str) -> frozenset[int]:
    from fontTools.ttLib import TTFont

    with TTFont(font_path, lazy=True) as tt:
        return frozenset(tt.getBestCmap())


def glyph_range_pbf(font_path: str | os.PathLike[str], fontstack: str, start: int, end: int) -> bytes:
    """The glyph protobuf of code points start..end (one 256-point range) of a TrueType font.

    Parameters
    ----------
    font_path
        A TrueType/OpenType font file.
    fontstack
        The font stack name written into the file (as the style's ``text-font`` names it).
    start, end
        The range, e.g. 0 and 255.

    Raises
    ------
    InvalidParameter
        Not a 256-code-point range.
    """
    check_range(start, end)
    font = ImageFont.truetype(os.fspath(font_path), GLYPH_SIZE_PX * OVERSAMPLE)
    glyphs = [g for cp in range(start, end + 1) if (g := render_glyph(font, cp)) is not None]
    stack = _string(1, fontstack) + _string(2, f"{start}-{end}")
    stack += b"".join(_message(3, _glyph_message(g)) for g in glyphs)
    return _message(1, stack)


# ---------------------------------------------------------------- protobuf wire format (varint, bytes)


def _varint(value: int) -> bytes:
    out = bytearray()
    while True:
        byte = value & 0x7F
        value >>= 7
        if value:
            out.append(byte | 0x80)
        else:
            out.append(byte)
            return bytes(out)


def _uint(field: int, value: int) -> bytes:
    return _varint(field << 3) + _varint(value)


def _sint(field: int, value: int) -> bytes:
    return _uint(field, (value << 1) ^ (value >> 63))  # zigzag


def _bytes(field: int, data: bytes) -> bytes:
    return _varint((field << 3) | 2) + _varint(len(data)) + data


def _string(field: int, text: str) -> bytes:
    return _bytes(field, text.encode("utf-8"))


def _message(field: int, body: bytes) -> bytes:
    return _bytes(field, body)


def _glyph_message(g: Glyph) -> bytes:
    body = _uint(1, g.codepoint)
    if g.bitmap.size:
        body += _bytes(2, g.bitmap.tobytes())
    body += _uint(3, g.width) + _uint(4, g.height)
    body += _sint(5, g.left) + _sint(6, g.top) + _uint(7, g.advance)
    return body
