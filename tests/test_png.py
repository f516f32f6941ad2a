"""The figures' PNG encoder (prsm_fmu.png) and prsm_fmu.figures.save: the pixels, resolution and
text a reader (Pillow) gets back are the ones given, and a saved figure's pixels are those of
matplotlib's own PNG of it."""

from __future__ import annotations

import io
import zlib

import numpy as np
import pytest

from prsm_fmu.png import SIGNATURE, encode_rgba

Image = pytest.importorskip("PIL.Image")


def _decode(data: bytes):
    im = Image.open(io.BytesIO(data))
    im.load()                   # reads every chunk (CRCs checked) and inflates the pixels
    return im


def test_random_images_read_back_pixel_for_pixel():
    # 40 images (seed 1), sides 1..300 px, random RGBA bytes (incompressible and all-equal
    # runs alike): each decodes to the same array
    rng = np.random.default_rng(1)
    n = 40
    for k in range(n):
        h, w = rng.integers(1, 301, size=2)
        px = rng.integers(0, 256, size=(h, w, 4), dtype=np.uint8)
        if k % 4 == 0:
            px[:] = px[0, 0]    # one colour: long runs
        im = _decode(encode_rgba(px, 110))
        assert im.mode == "RGBA" and im.size == (w, h)
        assert np.array_equal(np.asarray(im), px), k
    print(f"{n} random images read back equal")


def test_resolution_and_text_as_pillow_reads_them():
    px = np.zeros((3, 2, 4), dtype=np.uint8)
    im = _decode(encode_rgba(px, 110, {"Software": "Matplotlib version3.11.2, x"}))
    # 110 dpi = 110 / 0.0254 px/m = 4330.71 -> 4331 px/m stored; read back 4331 * 0.0254 =
    # 110.0074 dpi
    assert im.info["dpi"] == pytest.approx((110.0074, 110.0074), abs=1e-9)
    assert im.info["Software"] == "Matplotlib version3.11.2, x"


def test_layout_rows_unfiltered_at_the_level_asked():
    px = np.arange(2 * 3 * 4, dtype=np.uint8).reshape(2, 3, 4)
    data = encode_rgba(px, 72, level=9)
    assert data.startswith(SIGNATURE)
    i = data.index(b"IDAT")
    n = int.from_bytes(data[i - 4:i], "big")
    rows = zlib.decompress(data[i + 4:i + 4 + n])
    # 2 rows of 1 filter byte (0: none) + 3 px × 4 bytes
    assert len(rows) == 2 * (1 + 12) and rows[0] == 0 and rows[13] == 0
    assert rows[1:13] == bytes(range(12)) and rows[14:] == bytes(range(12, 24))


@pytest.mark.parametrize("pixels, dpi, word", [
    (np.zeros((2, 2, 3), np.uint8), 110, "pixels"),
    (np.zeros((2, 2, 4), np.float64), 110, "pixels"),
    (np.zeros((0, 2, 4), np.uint8), 110, "pixels"),
    (np.zeros((2, 2, 4), np.uint8), 0.0, "dpi"),
    (np.zeros((2, 2, 4), np.uint8), float("nan"), "dpi"),
])
def test_bad_input_one_line_naming_it(pixels, dpi, word):
    with pytest.raises(ValueError) as e:
        encode_rgba(pixels, dpi)
    msg = str(e.value)
    assert msg.startswith(word) and "\n" not in msg and "must be" in msg


@pytest.mark.parametrize("figsize, pixels", [
    ((4.0, 3.0), (440, 330)),        # 4 × 110 = 440, 3 × 110 = 330
    ((4.3, 3.07), (473, 337)),       # 4.3 × 110 = 473; 3.07 × 110 = 337.7: 337, Agg truncates
    ((10.5, 1.6), (1155, 176)),      # 10.5 × 110 = 1155; 1.6 × 110 = 176
])
def test_a_saved_figure_has_the_pixels_and_text_of_matplotlibs_png(tmp_path, figsize, pixels):
    # a figure with lines, text, a legend and a grid: prsm_fmu.figures.save against
    # matplotlib's savefig(png) at the same dpi, at sizes whose pixels are whole or not
    pytest.importorskip("matplotlib")
    from prsm_fmu.figures import save, subplots

    fig, ax = subplots(figsize=figsize)
    t = np.linspace(0.0, 1.0, 200)
    ax.plot(t, np.sin(7 * t), label="sin")
    ax.step(t, np.cos(3 * t), where="post", ls="--", label="cos")
    ax.set_title("a title\nsecond line", fontsize=10)
    ax.set_xlabel("time [ms]")
    ax.legend(fontsize=8)
    ax.grid(True)
    ref = tmp_path / "ref.png"
    fig.savefig(ref, dpi=110, format="png")
    ours = save(fig, tmp_path / "ours.png")
    a, b = Image.open(ref), _decode(ours.read_bytes())
    assert (a.mode, a.size) == (b.mode, b.size) == ("RGBA", pixels)
    assert np.array_equal(np.asarray(a), np.asarray(b))
    assert a.info["Software"] == b.info["Software"] and a.info["dpi"] == b.info["dpi"]
