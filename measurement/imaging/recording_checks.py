"""Checks that a recording is whole before it is measured (issue 11).

* :func:`check_size`: frame and pixel counts a recording may hold in memory;
* :func:`check_tiff_complete`: a multi-page TIFF cut short or with a damaged page chain is refused
  (page chain past the end of the file, frame count in the header vs pages present, page
  headers, tag values and pixel data inside the file, no frames lost from the chain) instead of
  being measured on the frames that survive;
* :func:`tifffile_messages`: tifffile logs a broken page chain instead of raising; collect it.
"""
from __future__ import annotations

import logging
import struct
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from abu_model.errors import AbuError


class RecordingError(AbuError):
    """A recording (file, folder or frame in it) cannot be read or has no usable frames."""


def _error(message: str) -> Exception:
    return RecordingError(message)


#: Limits of a recording held in memory (the report's camera stores 3072 frames per run).
MAX_FRAMES = 200_000
MAX_PIXELS = 4 * 2**30  # 4 GiB of 8-bit pixels


def check_size(shape: tuple[int, ...], where: str) -> None:
    """Refuse a recording whose frame count or pixel count is beyond what is held in memory."""
    n = int(shape[0]) if len(shape) == 3 else 1
    pixels = int(np.prod([int(s) for s in shape], dtype=np.float64))
    if n > MAX_FRAMES:
        raise _error(f"{where}: {n} frames; at most {MAX_FRAMES} are read (the report's "
                             "camera stores 3072 per run)")
    if pixels > MAX_PIXELS:
        raise _error(f"{where}: {pixels / 2**30:.1f} GiB of pixels {tuple(shape)}; at "
                             f"most {MAX_PIXELS / 2**30:.0f} GiB are held in memory")



@contextmanager
def tifffile_messages():
    """Collect tifffile's log messages (it logs a broken page chain instead of raising)."""
    logger = logging.getLogger("tifffile")
    messages: list[str] = []

    class _Collect(logging.Handler):
        def emit(self, record: logging.LogRecord) -> None:
            messages.append(record.getMessage())

    handler = _Collect(logging.WARNING)
    old_propagate = logger.propagate
    logger.addHandler(handler)
    logger.propagate = False
    try:
        yield messages
    finally:
        logger.removeHandler(handler)
        logger.propagate = old_propagate


#: Unreferenced bytes tolerated at the end of a TIFF (tifffile pads 16 bytes).
TIFF_TAIL_SLACK = 64


def check_tiff_complete(p: Path, tif, messages: list[str]) -> None:
    """Refuse a truncated or damaged multi-page TIFF instead of measuring the pages left.

    Three independent checks: tifffile found a page offset past the end of the file (a cut
    page chain); the frame count the writer put in the header (tifffile's shaped metadata)
    differs from the pages present; a page's pixel data extends past the end of the file.
    """
    size = p.stat().st_size
    n_pages = len(tif.pages)
    broken = [m for m in messages if "offset" in m.lower() or "corrupt" in m.lower()
              or "invalid" in m.lower()]
    if broken:
        raise _error(f"TIFF '{p}' is truncated or damaged: after page {n_pages - 1} the "
                             f"page chain points outside the file ({size} bytes): "
                             f"{' '.join(broken[0].split())}")
    shaped = tif.shaped_metadata
    if shaped and len(shaped) == 1 and isinstance(shaped[0], dict) and "shape" in shaped[0]:
        shape = tuple(int(s) for s in shaped[0]["shape"])
        check_size(shape, f"TIFF '{p}'")
        page_size = max(1, int(np.prod(tif.pages[0].shape)))
        expected = max(1, int(np.prod(shape)) // page_size)
        contiguous = n_pages == 1 and expected > 1
        stored = tif.pages[0].dataoffsets[0] + expected * tif.pages[0].databytecounts[0] \
            if contiguous and tif.pages[0].dataoffsets else None
        if contiguous and stored is not None and stored > size:
            raise _error(f"TIFF '{p}' is truncated: its header says {expected} frames "
                                 f"{shape[-1]}x{shape[-2]} px ({stored} bytes), the file has "
                                 f"{size} bytes")
        if not contiguous and n_pages != expected:
            raise _error(f"TIFF '{p}': its header says {expected} frames, the file holds "
                                 f"{n_pages} pages")
    check_size((n_pages,) + tuple(tif.pages[0].shape[-2:]), f"TIFF '{p}'")
    # Parsing a page's header is most of the cost of this check (~0.2 ms a page): parse each
    # once, and keep them for the reader (tif.series, asarray) that follows.
    tif.pages.cache = True
    with open(p, "rb") as handle:
        header_ends = [_ifd_end(handle, tif, page.offset) for page in tif.pages]
    referenced = 0
    for i, page in enumerate(tif.pages):
        header_end = header_ends[i]
        if header_end > size:
            raise _error(f"TIFF '{p}' is truncated: the header of frame {i} ends at byte "
                                 f"{header_end}, the file has {size} bytes")
        ends = [o + c for o, c in zip(page.dataoffsets, page.databytecounts)]
        if ends and max(ends) > size:
            raise _error(f"TIFF '{p}' is truncated: the data of frame {i} ends at byte "
                                 f"{max(ends)}, the file has {size} bytes")
        tag_ends = [t.valueoffset + t.valuebytecount for t in page.tags.values()]
        referenced = max([referenced, header_end, *ends, *tag_ends])
    if size - referenced > TIFF_TAIL_SLACK:
        # A page chain cut short (a damaged next-page offset) leaves frames nobody refers to.
        raise _error(f"TIFF '{p}' is damaged: {size - referenced} bytes after the last "
                             f"of its {n_pages} frames belong to no frame (frames lost from the "
                             "page chain?)")


def _ifd_end(handle, tif, offset: int) -> int:
    """The byte just past the page header (IFD) at ``offset``: tag count, tags, next-IFD
    offset, read from the open file (tifffile does not keep it)."""
    t = tif.tiff
    handle.seek(offset)
    raw = handle.read(t.tagnosize)
    if len(raw) < t.tagnosize:
        return offset + t.tagnosize
    (count,) = struct.unpack(t.byteorder + ("Q" if t.tagnosize == 8 else "H"), raw)
    return offset + t.tagnosize + count * t.tagsize + t.offsetsize
