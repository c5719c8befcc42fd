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
import mmap
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
    if n_pages > 2 and _uniform_stack_whole(p, tif, size):
        return  # every page header read in one vectorised pass (below): whole and contiguous
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


#: Bytes per value of the TIFF field types (TIFF 6.0 and BigTIFF).
_TYPE_SIZES = {1: 1, 2: 1, 3: 2, 4: 4, 5: 8, 6: 1, 7: 1, 8: 2, 9: 4, 10: 8, 11: 4, 12: 8, 13: 4,
               16: 8, 17: 8, 18: 8}
_STRIP_TAGS = (273, 279)  # StripOffsets, StripByteCounts


def _uniform_stack_whole(p: Path, tif, size: int) -> bool:
    """True if pages 1.. of the TIFF are whole by the same tests as the page-by-page loop of
    :func:`check_tiff_complete`, checked at once for the usual layout: a camera's or our own
    writer's stack, whose page headers after the first are alike except for the one-strip
    offset, and whose pixels lie contiguous (what the memory-mapped reader relies on).

    Accept-only: anything else (other tags, strips, types, a page header out of place or cut,
    a chain that does not match tifffile's page count) returns False and the page-by-page
    check decides, with its messages. Parsing 3072 page headers with tifffile cost ~0.2 s of
    the 0.68 s a 3072-frame recording lasts; this reads them in ~5 ms (measured).
    """
    t = tif.tiff
    first = tif.pages[0]
    n_pages = len(tif.pages)
    if (t.offsetsize not in (4, 8) or len(first.dataoffsets) != 1
            or first.dataoffsets[0] + n_pages * first.databytecounts[0] > size):
        return False
    bo = t.byteorder
    with open(p, "rb") as handle, mmap.mmap(handle.fileno(), 0, access=mmap.ACCESS_READ) as mm:
        # walk the chain from page 1 (offsets only), as tifffile did to count the pages
        offsets = []
        next_fmt = bo + ("Q" if t.offsetsize == 8 else "I")
        count_fmt = bo + ("Q" if t.tagnosize == 8 else "H")
        off = first.offset
        (n0,) = struct.unpack_from(count_fmt, mm, off)
        off = struct.unpack_from(next_fmt, mm, off + t.tagnosize + n0 * t.tagsize)[0]
        n_tags = None
        while off and len(offsets) < n_pages:
            if off + t.tagnosize > size:
                return False
            (n,) = struct.unpack_from(count_fmt, mm, off)
            if n_tags is None:
                n_tags = n
            if n != n_tags or off + t.tagnosize + n * t.tagsize + t.offsetsize > size:
                return False
            offsets.append(off)
            off = struct.unpack_from(next_fmt, mm, off + t.tagnosize + n * t.tagsize)[0]
        if off != 0 or len(offsets) != n_pages - 1 or not n_tags:
            return False
        raw = np.frombuffer(mm, dtype=np.uint8)
        start = np.asarray(offsets, dtype=np.int64) + t.tagnosize
        entries = raw[start[:, None] + np.arange(n_tags * t.tagsize)]  # (P, n * tagsize) bytes
        del raw
    value_size = t.tagsize - 4 - (4 if t.offsetsize == 4 else 8)
    cdt = np.dtype(bo + ("u4" if t.offsetsize == 4 else "u8"))
    ent = entries.view(np.dtype([("code", bo + "u2"), ("type", bo + "u2"), ("count", cdt),
                                 ("value", f"V{value_size}")])).reshape(len(offsets), n_tags)
    codes, types, counts = ent["code"], ent["type"], ent["count"]
    if ((codes != codes[:1]).any() or (types != types[:1]).any()
            or (counts != counts[:1]).any()):
        return False
    code = codes[0].tolist()
    if any(c not in code for c in _STRIP_TAGS) or any(ty not in _TYPE_SIZES
                                                      for ty in types[0].tolist()):
        return False
    i_off, i_cnt = code.index(273), code.index(279)
    if counts[0, i_off] != 1 or counts[0, i_cnt] != 1:
        return False
    uint = {1: "u1", 3: "u2", 4: "u4", 16: "u8"}
    values = entries.reshape(len(offsets), n_tags, t.tagsize)[:, :, t.tagsize - value_size:]
    strip = []
    for i in (i_off, i_cnt):
        ty = int(types[0, i])
        if ty not in uint:
            return False
        strip.append(values[:, i, :_TYPE_SIZES[ty]].copy().view(bo + uint[ty])[:, 0]
                     .astype(np.int64))
    # all other tags the same as on page 1 (out-of-line values shared, as tifffile writes)
    others = [i for i in range(n_tags) if i not in (i_off, i_cnt)]
    if (values[:, others] != values[:1, others]).any():
        return False
    frame_bytes = int(first.databytecounts[0])
    expected = first.dataoffsets[0] + frame_bytes * np.arange(1, n_pages, dtype=np.int64)
    if (strip[1] != frame_bytes).any() or (strip[0] != expected).any():
        return False
    # ends of page 1's out-of-line tag values (shared by all pages) and of every header
    sizes = np.array([_TYPE_SIZES[ty] for ty in types[0].tolist()], dtype=np.int64)
    nbytes = counts[0].astype(np.int64) * sizes
    tag_ends = [0]
    for i in np.flatnonzero(nbytes > value_size).tolist():
        (voff,) = struct.unpack(bo + ("I" if t.offsetsize == 4 else "Q"),
                                values[0, i].tobytes()[:t.offsetsize])
        tag_ends.append(voff + int(nbytes[i]))
    header_end = max(offsets) + t.tagnosize + n_tags * t.tagsize + t.offsetsize
    page0_end = max([first.offset + t.tagnosize + n0 * t.tagsize + t.offsetsize,
                     *(o + c for o, c in zip(first.dataoffsets, first.databytecounts)),
                     *(tg.valueoffset + tg.valuebytecount for tg in first.tags.values())])
    referenced = max(max(tag_ends), header_end, int(strip[0][-1] + strip[1][-1]), page0_end)
    return referenced <= size and size - referenced <= TIFF_TAIL_SLACK
