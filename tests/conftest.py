"""Shared fixtures: the real data sets in ../shared/data (skipped with a reason when absent)."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

import matplotlib

matplotlib.use("Agg")

REPO = Path(__file__).resolve().parents[1]
SHARED_DATA = Path(os.environ.get("VIBROSCOPE_SHARED_DATA", REPO.parent / "shared" / "data"))


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """Path of ../shared/data; skips the test when the data sets are not beside the repository."""
    if not SHARED_DATA.is_dir():
        pytest.skip(f"real data sets not found at {SHARED_DATA} (clone with ../shared beside the repo)")
    return SHARED_DATA


def _check_png(path, min_size=(300, 200), min_colours=8):
    """A written figure is a PNG of at least `min_size` pixels with more than `min_colours`
    colours (not blank); returns its (width, height)."""
    from PIL import Image

    with Image.open(path) as im:
        assert im.format == "PNG", path
        assert im.size[0] >= min_size[0] and im.size[1] >= min_size[1], (path, im.size)
        colours = im.convert("RGB").getcolors(1 << 16)
        assert colours is None or len(colours) > min_colours, (path, len(colours))
        return im.size


@pytest.fixture
def check_png():
    """:func:`_check_png`: asserts a figure file is a real, non-blank PNG (not just a big file)."""
    return _check_png
