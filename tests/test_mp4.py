"""The one MP4 writer (tonguevis.render.mp4.write_mp4): picture and sound, atomic, errors naming the file."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("imageio_ffmpeg")

from tonguevis.errors import ExportError  # noqa: E402
from tonguevis.io.recording import Audio  # noqa: E402
from tonguevis.render.mp4 import probe_streams, write_mp4  # noqa: E402

SIZE = (64, 48)  # width, height


def pictures(n: int, size=SIZE):
    """``n`` RGBA pictures (the writer drops the alpha), a grey ramp over time."""
    for k in range(n):
        yield np.full((size[1], size[0], 4), 10 * k, dtype=np.uint8)


def test_a_video_with_its_sound_and_nothing_else_left(tmp_path):
    out = tmp_path / "sub" / "v.mp4"
    tone = Audio(0.1 * np.sin(2 * np.pi * 440 * np.arange(8000) / 16000.0), 16000.0)  # 0.5 s
    assert write_mp4(out, pictures(10), SIZE, 20, audio=tone) == out
    assert sorted(probe_streams(out)) == ["audio", "video"]
    assert [p.name for p in out.parent.iterdir()] == ["v.mp4"]
    write_mp4(out, pictures(5), SIZE, 20)  # no sound: a silent video over the old one
    assert probe_streams(out) == ["video"]


def test_a_picture_of_the_wrong_size_is_an_error_that_leaves_the_old_file(tmp_path):
    out = tmp_path / "v.mp4"
    out.write_bytes(b"the user's file")

    def wrong():
        yield from pictures(3)
        yield np.zeros((SIZE[1] + 2, SIZE[0], 3), dtype=np.uint8)

    with pytest.raises(ExportError, match=r"64x50 pixels in a 64x48 video") as error:
        write_mp4(out, wrong(), SIZE, 20)
    assert error.value.path == str(out)
    assert out.read_bytes() == b"the user's file"
    assert [p.name for p in tmp_path.iterdir()] == ["v.mp4"]  # the temporary file is gone


def test_a_failure_while_rendering_stops_the_export_and_leaves_nothing(tmp_path):
    out = tmp_path / "v.mp4"

    def failing():
        yield from pictures(2)
        raise KeyError("rendering failed")

    with pytest.raises(KeyError, match="rendering failed"):
        write_mp4(out, failing(), SIZE, 20)
    assert list(tmp_path.iterdir()) == []
