"""Figure files of every command (``abu measure``, ``measure-summary``, ``simulate``, ``design``,
``identify``, ``next``): one format choice, one resolution, written atomically.

* PNG (default) at :data:`PNG_DPI` dots per inch (stored in the PNG's pHYs chunk): the
  figures are 6.5-8 in wide, so a PNG is 1300-1600 px wide and stays sharp printed at full
  text width;
* PDF or SVG on request (vector: any size), without creation dates so that the same data give
  the same bytes.

matplotlib is not imported at module level: callers pass a figure they drew (the measurement
imports matplotlib only when it plots).
"""
from __future__ import annotations

import io
import os
import struct
import zlib
from pathlib import Path

from abu_model.atomic_io import atomic_write_bytes
from abu_model.errors import ParameterError

#: Formats a figure can be written in (``--figure-format``).
FIGURE_FORMATS = ("png", "pdf", "svg")
#: Resolution of PNG figures [dots per inch] (>= 150 for print: a 7.5 in figure is 1125 px wide).
PNG_DPI = 150
#: No creation dates in vector files (reproducible bytes).
_METADATA = {"pdf": {"CreationDate": None}, "svg": {"Date": None}, "png": {}}
#: Settings every figure file is drawn with. Unhinted glyphs: the outlines themselves, as in
#: the PDF; FreeType's default auto-hinter snaps them to the pixel grid, which helps a screen
#: at 8 pt and 96 dpi, not print at :data:`PNG_DPI`: it cut the underscore of "omega_dot" off
#: the measurement's legend at 150 dpi, and cost 40 ms of the measurement's 0.3 s of figures.
DRAW_RC = {"text.hinting": "no_hinting"}


def check_figure_format(figure_format: str, option: str = "figure_format") -> str:
    """``figure_format`` lower-cased if it is one of :data:`FIGURE_FORMATS`, else
    ParameterError naming ``option``."""
    fmt = str(figure_format).lower().lstrip(".")
    if fmt not in FIGURE_FORMATS:
        raise ParameterError(option, figure_format, f"one of {', '.join(FIGURE_FORMATS)}")
    return fmt


def figure_path(path: str | os.PathLike, figure_format: str = "png") -> Path:
    """``path`` with the suffix of ``figure_format`` (``beta.png`` -> ``beta.pdf``)."""
    return Path(path).with_suffix("." + check_figure_format(figure_format))


def save_figure(fig, path: str | os.PathLike, figure_format: str = "png") -> Path:
    """Write the matplotlib figure ``fig`` to ``path`` (its suffix replaced by the format's),
    atomically; returns the path written."""
    fmt = check_figure_format(figure_format)
    target = figure_path(path, fmt)
    import matplotlib  # loaded already: ``fig`` is a matplotlib figure
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    # the plain Agg canvas (the commands' own, and pyplot's without a display); a GUI
    # canvas is left to savefig, which draws off screen
    if fmt == "png" and type(fig.canvas) is FigureCanvasAgg:
        atomic_write_bytes(target, _png_bytes(fig))
        return target
    buffer = io.BytesIO()
    # fixed SVG ids (else random clip-path names)
    with matplotlib.rc_context({**DRAW_RC, "svg.hashsalt": "abu-friction"}):
        fig.savefig(buffer, format=fmt, dpi=PNG_DPI, metadata=_METADATA[fmt],
                    **({"pil_kwargs": {"compress_level": 1}} if fmt == "png" else {}))
    atomic_write_bytes(target, buffer.getvalue())
    return target


def _png_bytes(fig) -> bytes:
    """``fig`` drawn by Agg at :data:`PNG_DPI` as a PNG: RGB when every pixel is opaque (the
    figures' white background), unfiltered rows, zlib level 1.

    The pixels are those ``fig.savefig(..., dpi=PNG_DPI)`` writes; only the encoding differs:
    Pillow's adaptive row filters cost 2/3 of its ~33 ms a figure and, on line art, give a
    larger file than no filter (measured on the measurement's two figures: 33 -> 10 ms,
    280 -> 240 kB)."""
    import matplotlib
    import numpy as np

    dpi0 = fig.dpi
    fig.set_dpi(PNG_DPI)
    try:
        with matplotlib.rc_context(DRAW_RC):
            fig.canvas.draw()
        rgba = np.asarray(fig.canvas.buffer_rgba())
    finally:
        fig.set_dpi(dpi0)
    opaque = bool((rgba[..., 3] == 255).all())
    height, width = rgba.shape[:2]
    channels = 3 if opaque else 4
    rows = np.empty((height, 1 + width * channels), np.uint8)
    rows[:, 0] = 0                                                # filter byte 0: none
    if opaque:
        # RGB out of RGBA as 3-byte items (one copy per pixel: 3.4x faster than the byte-wise
        # strided copy of rgba[..., :3], 2 ms against 7 ms for a 1200x1260 figure)
        src = np.ndarray((height, width), dtype="V3", buffer=rgba,
                         strides=(rgba.strides[0], rgba.strides[1]))
        rows[:, 1:].view("V3")[:] = src
    else:
        rows[:, 1:] = rgba.reshape(height, -1)
    ppm = round(PNG_DPI / 0.0254)                                 # pixels per metre

    def chunk(kind: bytes, data: bytes) -> bytes:
        return (struct.pack(">I", len(data)) + kind + data
                + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF))

    software = f"Matplotlib version{matplotlib.__version__}, https://matplotlib.org/"
    return b"".join((
        b"\x89PNG\r\n\x1a\n",
        chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 2 if opaque else 6, 0, 0, 0)),
        chunk(b"pHYs", struct.pack(">IIB", ppm, ppm, 1)),
        chunk(b"tEXt", b"Software\0" + software.encode("latin-1")),
        chunk(b"IDAT", zlib.compress(rows, 1)),
        chunk(b"IEND", b"")))


def _texts(fig) -> list:
    """The texts a reader sees: titles, axis and tick labels in view, legends, figure texts."""
    out = list(fig.texts)
    for legend in fig.legends:
        out += legend.get_texts()
    axes = list(fig.axes)
    for ax in list(axes):
        axes += [a for a in getattr(ax, "child_axes", []) if a not in axes]
    for ax in axes:
        out += [ax.title, getattr(ax, "_left_title", None), getattr(ax, "_right_title", None)]
        for axis in (ax.xaxis, ax.yaxis):
            out += [axis.label, axis.get_offset_text()]
            for tick in axis._update_ticks():   # the ticks in view (others are not drawn)
                out += [tick.label1, tick.label2]
        if ax.get_legend() is not None:
            out += ax.get_legend().get_texts()
    return [t for t in out if t is not None and t.get_visible() and t.get_text().strip()]


def layout_problems(fig) -> list[str]:
    """What a reader of the drawn ``fig`` would object to in its layout: a text cut by the
    canvas edge, two texts overlapping, a legend on a panel's data area. Empty when none."""
    import matplotlib

    with matplotlib.rc_context(DRAW_RC):   # the text extents of the file written
        return _layout_problems(fig)


def _layout_problems(fig) -> list[str]:
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    canvas = fig.bbox
    texts = _texts(fig)
    boxes = [t.get_window_extent(renderer) for t in texts]
    problems = []
    for t, b in zip(texts, boxes):
        if b.x0 < canvas.x0 - 1 or b.y0 < canvas.y0 - 1 or b.x1 > canvas.x1 + 1 \
                or b.y1 > canvas.y1 + 1:
            problems.append(f"text {t.get_text()!r} leaves the figure")
    for i in range(len(boxes)):
        for j in range(i + 1, len(boxes)):
            a, b = boxes[i].padded(-0.5), boxes[j].padded(-0.5)
            if a.overlaps(b) and texts[i].get_text() != texts[j].get_text():
                problems.append(f"texts {texts[i].get_text()!r} and {texts[j].get_text()!r} "
                                "overlap")
    legends = list(fig.legends) + [ax.get_legend() for ax in fig.axes if ax.get_legend()]
    for legend in legends:
        lb = legend.get_window_extent(renderer)
        for ax in fig.axes:
            if lb.overlaps(ax.bbox):
                problems.append(f"a legend ({legend.get_texts()[0].get_text()!r}...) lies on "
                                "a panel")
    return problems
