"""The batch contact sheet's labels: broken at spaces to fit a cell, measured in pixels (the first version cut at
the width of an 'm', so 'donut-wood-angle45' lost its '5' and a note stopped mid-word), '...' when text is left."""

from __future__ import annotations

import pytest

from gt2gs_blender.app.batch.sheet import NOTE_SCALE, TEXT_W, _width, wrapped

NOTE = "not measured (the preset's Measure Result is off)"


@pytest.mark.parametrize("text", ["donut-wood-angle45", "donut-brick-angle45", NOTE])
def test_a_label_that_fits_in_its_lines_is_shown_whole_broken_at_spaces(text):
    lines = wrapped(text, NOTE_SCALE, 2)
    assert " ".join(lines) == text
    assert all(_width(line, NOTE_SCALE) <= TEXT_W for line in lines)


def test_a_label_too_long_for_its_lines_ends_with_an_ellipsis_within_the_cell():
    text = " ".join(["texture"] * 40)
    lines = wrapped(text, NOTE_SCALE, 2)
    assert len(lines) == 2 and lines[-1].endswith("...")
    assert all(_width(line, NOTE_SCALE) <= TEXT_W for line in lines)
    assert all(word == "texture" for line in lines for word in line.removesuffix("...").split())


def test_a_word_wider_than_a_line_is_cut_to_fit_and_says_so():
    (line,) = wrapped("x" * 200, NOTE_SCALE, 1)
    assert _width(line, NOTE_SCALE) <= TEXT_W and line.endswith("x...")
