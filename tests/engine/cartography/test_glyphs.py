"""Glyph PBFs: decoded with protobuf's own runtime (a message type declared here from the format's fields),
so the hand-written wire format is checked by an independent reader; and the SDF is a distance field."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

from engine.cartography.glyphs import BORDER_PX, glyph_range_pbf
from engine.errors import InvalidParameter

FONT = Path("/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf")


def glyphs_message_class():
    """MapLibre's glyphs.proto (package llmr.glyphs), declared field by field."""
    f = descriptor_pb2.FileDescriptorProto(name="glyphs_test.proto", package="llmr.glyphs", syntax="proto2")
    opt, req, rep = (
        descriptor_pb2.FieldDescriptorProto.LABEL_OPTIONAL,
        descriptor_pb2.FieldDescriptorProto.LABEL_REQUIRED,
        descriptor_pb2.FieldDescriptorProto.LABEL_REPEATED,
    )
    t = descriptor_pb2.FieldDescriptorProto
    glyph = f.message_type.add(name="glyph")
    for name, num, typ, label in [
        ("id", 1, t.TYPE_UINT32, req),
        ("bitmap", 2, t.TYPE_BYTES, opt),
        ("width", 3, t.TYPE_UINT32, req),
        ("height", 4, t.TYPE_UINT32, req),
        ("left", 5, t.TYPE_SINT32, req),
        ("top", 6, t.TYPE_SINT32, req),
        ("advance", 7, t.TYPE_UINT32, req),
    ]:
        glyph.field.add(name=name, number=num, type=typ, label=label)
    stack = f.message_type.add(name="fontstack")
    stack.field.add(name="name", number=1, type=t.TYPE_STRING, label=req)
    stack.field.add(name="range", number=2, type=t.TYPE_STRING, label=req)
    stack.field.add(name="glyphs", number=3, type=t.TYPE_MESSAGE, label=rep, type_name=".llmr.glyphs.glyph")
    top = f.message_type.add(name="glyphs")
    top.field.add(name="stacks", number=1, type=t.TYPE_MESSAGE, label=rep, type_name=".llmr.glyphs.fontstack")
    pool = descriptor_pool.DescriptorPool()
    pool.Add(f)
    return message_factory.GetMessageClass(pool.FindMessageTypeByName("llmr.glyphs.glyphs"))


@pytest.fixture(scope="module")
def latin():
    assert FONT.is_file(), f"{FONT} missing: apt-get install fonts-dejavu-core"
    msg = glyphs_message_class()()
    msg.ParseFromString(glyph_range_pbf(FONT, "DejaVu Sans Book", 0, 255))
    assert msg.IsInitialized()
    return msg


def test_one_stack_with_the_name_and_range(latin):
    assert len(latin.stacks) == 1
    assert (latin.stacks[0].name, latin.stacks[0].range) == ("DejaVu Sans Book", "0-255")


def test_labels_characters_are_all_there(latin):
    ids = {g.id for g in latin.stacks[0].glyphs}
    needed = {ord(c) for c in "0123456789 -mftabcxyzABCXYZ.,°"} | {0x2212}.intersection(range(256))
    assert needed <= ids
    assert not ids & set(range(32)), "control characters would draw as boxes"


def test_bitmaps_are_signed_distance_fields(latin):
    glyphs = {g.id: g for g in latin.stacks[0].glyphs}
    space = glyphs[ord(" ")]
    assert (space.width, space.height, space.bitmap) == (0, 0, b"") and space.advance > 0
    one = glyphs[ord("1")]
    w, h = one.width + 2 * BORDER_PX, one.height + 2 * BORDER_PX
    sdf = np.frombuffer(one.bitmap, np.uint8).reshape(h, w)
    # The border is outside the ink: below the outline value 191; the stem of the "1" is inside: above it.
    assert sdf[0, :].max() < 150 and sdf[:, 0].max() < 150
    assert sdf[h // 2].max() > 200
    # A distance field, not a mask: values step gently (at most 255/8 per pixel, plus rounding).
    assert np.abs(np.diff(sdf.astype(int), axis=1)).max() <= 255 / 8 * 1.5
    assert 10 <= one.advance <= 20  # a digit of a 24 px em
    # The top is signed (zigzag): a digit's top edge sits a few pixels below MapLibre's top line.
    assert -15 < one.top < 0 and one.left >= 0


def test_wider_letters_are_wider(latin):
    glyphs = {g.id: g for g in latin.stacks[0].glyphs}
    assert glyphs[ord("m")].width > glyphs[ord("i")].width
    assert glyphs[ord("m")].advance > glyphs[ord("f")].advance


@pytest.mark.parametrize("start, end", [(0, 10), (1, 256), (65536, 65791)])
def test_a_bad_range_is_refused(start, end):
    with pytest.raises(InvalidParameter, match=f"glyph range {start}-{end}"):
        glyph_range_pbf(FONT, "DejaVu Sans Book", start, end)
