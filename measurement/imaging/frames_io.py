"""Read and write high-speed camera recordings as one (N, H, W) uint8 array.

Accepted inputs (``read_recording``):

* a folder of 8-bit grayscale frames (PNG, BMP or TIFF), read in natural name order
  (``f2.png`` before ``f10.png``); a folder holding a single multi-page TIFF or ``.npy`` stack
  (e.g. a twin's output folder) is read as that stack;
* a multi-page TIFF (tifffile);
* a ``.npy`` stack (N, H, W) uint8, memory-mapped (nothing is read until used);
* a Photron MRAW (its .cih, .cihx or .mraw) or a Phantom .cine file (:mod:`camera_files`);
* any video file OpenCV can decode (converted to grayscale; lossy codecs alter the pixels).

Frames may be 8- or 16-bit, grey or colour (RGB / BGR, alpha ignored): 16-bit and colour frames
are converted to 8-bit grey on reading (:mod:`sample_formats`; the recording's ``source`` says
what was converted). Other sample types (float, 32-bit) are refused.

Every problem raises :class:`RecordingError` naming the file and, where it applies, the frame.
A multi-page TIFF or ``.npy`` stack of 3072 frames of 256x256 reads in well under a second;
3072 separate image files take longer than tracking them (see the benchmark).
"""
from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np


from measurement.imaging.compression import fourcc_text
from measurement.imaging import sample_formats as fmt
from measurement.imaging.frame_rate import rate_from_render_meta, rate_from_tiff
from measurement.imaging.recording_checks import (  # noqa: F401  (re-exported names)
    MAX_FRAMES, MAX_PIXELS, RecordingError, check_size, check_tiff_complete, tifffile_messages)
from measurement.imaging.recording import (  # noqa: F401  (re-exported names)
    FRAME_SUFFIXES, TIFF_SUFFIXES, VIDEO_SUFFIXES, Recording, check_stack, natural_key)
from measurement.imaging.frames_write import (  # noqa: F401  (re-exported names)
    write_frame_folder, write_multipage_tiff, write_npy)

def read_recording(path: str | os.PathLike, *, mmap: bool = True) -> Recording:
    """Read a recording (folder of frames, multi-page TIFF, ``.npy`` stack or video).

    Args:
        path: file or folder.
        mmap: memory-map ``.npy`` stacks and contiguous uncompressed TIFF stacks (fast open;
            pages are read on first use).

    Returns:
        A :class:`Recording` with ``frames`` of shape (N, H, W), dtype uint8.

    Raises:
        RecordingError: nonexistent path, empty folder, unreadable or missing frame, wrong
            dtype (not uint8), colour frames or frames of differing sizes; the message names
            the file and the frame.
    """
    p = Path(path)
    if not p.exists():
        raise RecordingError(f"recording '{p}' does not exist")
    if p.is_dir():
        return _read_folder(p)
    suffix = p.suffix.lower()
    if suffix == ".npy":
        return _read_npy(p, mmap=mmap)
    if suffix in TIFF_SUFFIXES:
        return _read_tiff(p, mmap=mmap)
    if suffix in (".cih", ".cihx", ".mraw", ".cine"):
        from measurement.imaging.camera_files import read_camera_file
        frames, info = read_camera_file(p, mmap=mmap)
        frames, note = _convert(frames)
        return Recording(check_stack(np.ascontiguousarray(frames), info.source),
                         info.source + note, fps_hz=info.fps_hz, fps_source=info.fps_source,
                         bit_depth=info.bit_depth, first_frame_time_s=info.first_frame_time_s)
    if suffix in (".csv", ".txt", ".json"):   # text: no recording (OpenCV would only fail)
        raise RecordingError(
            f"'{p}' is a text file, not a recording (frames); a tracks CSV of 'abu track' is "
            "measured with 'abu measure --tracks'")
    if suffix in (".png", ".bmp"):
        frame, colour = _read_single_frame(p, 0, None)
        frame, note = _convert(frame[np.newaxis], was_colour=colour)
        return Recording(frame, f"image file {p}{note}", [p.name])
    return _read_video(p)


def _check_sample_type(dtype: np.dtype, where: str) -> None:
    if dtype not in fmt.SAMPLE_TYPES:
        raise RecordingError(f"{where}: frames have dtype {dtype}; expected 8- or 16-bit "
                             "unsigned samples (uint8 or uint16), grey or colour")


def _grey(img: np.ndarray, where: str, order: str = "BGR") -> np.ndarray:
    """One image as grey: (H, W) as is, (H, W, 3|4) colour (``order``, alpha ignored) by luma."""
    if img.ndim == 3 and img.shape[-1] in (3, 4):
        _check_sample_type(img.dtype, where)
        return fmt.luma(img, order)
    if img.ndim != 2:
        raise RecordingError(f"{where} is an image of shape {img.shape}; expected grey (H, W) or "
                             "colour (H, W, 3|4)")
    return img


def _convert(frames: np.ndarray, *, colour_axis: bool = False,
             order: str = "RGB", was_colour: bool = False) -> tuple[np.ndarray, str]:
    """uint8 grey frames and the source text's conversion note ('' if none); ``colour_axis``:
    the last axis holds colour samples to convert; ``was_colour``: converted already."""
    if not isinstance(frames, np.ndarray) or frames.dtype not in fmt.SAMPLE_TYPES:
        return frames, ""  # check_stack names the problem
    colour = colour_axis and frames.shape[-1] in (3, 4)
    if colour:
        frames = fmt.luma(frames, order)
    frames, note = fmt.to_uint8(frames)
    return frames, fmt.describe(colour or was_colour, note)


def _read_npy(p: Path, *, mmap: bool) -> Recording:
    try:
        frames = np.load(p, mmap_mode="r" if mmap else None, allow_pickle=False)
    except (ValueError, OSError, EOFError) as exc:
        raise RecordingError(f"cannot read .npy stack '{p}': {exc}") from None
    if not isinstance(frames, np.ndarray):  # an .npz archive under a .npy name
        raise RecordingError(f"'{p}' is not a .npy array (an archive?); expected one (N, H, W) "
                             "uint8 stack")
    if frames.ndim == 2 and frames.dtype in fmt.SAMPLE_TYPES:
        # A 2-D array would be read as one frame of N x H: almost surely a mistake.
        raise RecordingError(f"'{p}' holds an array of shape {frames.shape}; expected a stack "
                             "(N, H, W) of 8-bit frames (save one frame as shape (1, H, W))")
    _check_sample_type(frames.dtype, f"'{p}'")
    check_size(frames.shape[:3], f"'{p}'")  # before anything is read into memory
    frames, note = _convert(frames, colour_axis=frames.ndim == 4, order="RGB")
    frames = check_stack(frames, f"'{p}'")
    if not frames.flags.c_contiguous:
        frames = np.ascontiguousarray(frames)
    return Recording(frames, f".npy stack {p}{note}")


def _mapped_series(p: Path, tif, series) -> np.ndarray | None:
    """The series memory-mapped where its pixels lie contiguous and uncompressed in the file
    (as every camera's and our own writer's stacks do), else None. Pages are read on first
    use: ``abu measure`` on 3072 frames saves the ~0.3 s copy of ``asarray`` (measured)."""
    offset = series.dataoffset
    if offset is None or series.dtype is None:
        return None
    dtype = np.dtype(series.dtype).newbyteorder(tif.byteorder)
    if not dtype.isnative:
        return None     # the conversions expect native samples: asarray swaps the bytes
    if offset + int(np.prod(series.shape)) * dtype.itemsize > p.stat().st_size:
        return None     # a cut file: asarray (and its messages) decides
    return np.memmap(p, dtype=dtype, mode="r", offset=offset, shape=tuple(series.shape))


def _read_tiff(p: Path, *, mmap: bool = True) -> Recording:
    import tifffile

    n_pages = None  # known once the structure is checked
    rate = (None, None, None)  # fps_hz, fps_source, first_frame_time_s
    try:
        with tifffile_messages() as messages, tifffile.TiffFile(p) as tif:
            pages = tif.pages
            if len(pages) == 0:
                raise RecordingError(f"TIFF '{p}' holds no frames")
            check_tiff_complete(p, tif, messages)
            rate = rate_from_tiff(p, tif)
            n_pages = len(pages)
            series = tif.series
            if len(series) > 1:
                _raise_differing_pages(p, tif)
            s = series[0]
            axes = s.axes
            if "S" in axes and not (axes.endswith("S") and s.shape[-1] in (3, 4)):
                raise RecordingError(f"TIFF '{p}': frames with samples on axes {axes}, shape "
                                     f"{s.shape}; expected grey or RGB(A) pages")
            _check_sample_type(s.dtype, f"TIFF '{p}'")
            colour = "S" in axes
            frames = _mapped_series(p, tif, s) if mmap else None
            if frames is None:
                frames = s.asarray()
    except RecordingError:
        raise
    except Exception as exc:  # tifffile raises many types on corrupt files
        colour = False
        rate = rate_from_render_meta(p)
        frames = _cv2_read_multi(p)  # e.g. LZW compression without the imagecodecs package
        if frames is None or n_pages is None or frames.shape[0] != n_pages:
            # the fallback only decodes what a checked structure describes, page for page
            raise RecordingError(f"cannot read TIFF '{p}': {' '.join(str(exc).split())}") \
                from None
    if colour:
        frames = fmt.luma(frames, "RGB")
    frames = frames.reshape((-1,) + frames.shape[-2:]) if frames.ndim > 3 else frames
    frames, note = _convert(frames, was_colour=colour)
    return Recording(check_stack(frames, f"TIFF '{p}'"), f"multi-page TIFF {p}{note}",
                     fps_hz=rate[0], fps_source=rate[1], first_frame_time_s=rate[2])


def _raise_differing_pages(p: Path, tif) -> None:
    """Name the first page whose shape or dtype differs from page 0."""
    first = tif.pages[0]
    for i, page in enumerate(tif.pages):
        if page.shape != first.shape or page.dtype != first.dtype:
            raise RecordingError(
                f"TIFF '{p}': frame {i} has shape {page.shape} and dtype {page.dtype}, frame 0 "
                f"has shape {first.shape} and dtype {first.dtype}; all frames must match")
    raise RecordingError(f"TIFF '{p}' holds several image series; expected one stack of frames")


def _cv2_read(f: Path) -> np.ndarray | None:
    import cv2

    return cv2.imread(str(f), cv2.IMREAD_UNCHANGED)


def _cv2_read_multi(p: Path) -> np.ndarray | None:
    """All pages of a TIFF via OpenCV (fallback for codecs tifffile lacks); None on failure."""
    import cv2

    level = cv2.utils.logging.getLogLevel()
    cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_SILENT)  # one line on stderr
    try:
        ok, pages = cv2.imreadmulti(str(p), flags=cv2.IMREAD_UNCHANGED)
    except cv2.error:
        ok, pages = False, []
    finally:
        cv2.utils.logging.setLogLevel(level)
    if not ok or not pages:
        return None
    pages = [_grey(page, f"TIFF '{p}': frame {i}") for i, page in enumerate(pages)]
    first = pages[0]
    for i, page in enumerate(pages):
        _check_sample_type(page.dtype, f"TIFF '{p}': frame {i}")
        if page.dtype != first.dtype:
            raise RecordingError(f"TIFF '{p}': frame {i} has dtype {page.dtype}, frame 0 has "
                                 f"{first.dtype}; all frames must match")
        if page.shape != first.shape:
            raise RecordingError(f"TIFF '{p}': frame {i} has shape {page.shape}, frame 0 has "
                                 f"shape {first.shape}; all frames must match")
    return np.stack(pages)


def _read_single_frame(f: Path, index: int, shape: tuple[int, int] | None,
                       dtype: np.dtype | None = None) -> tuple[np.ndarray, bool]:
    """Read one frame as grey, uint8 or uint16 (colour converted); check it against ``shape``
    and ``dtype`` (the first frame's). Returns (frame, whether it was colour)."""
    label = f"frame {index} ('{f}')"
    order = "BGR"  # OpenCV's
    if f.suffix.lower() in TIFF_SUFFIXES:
        import tifffile

        try:
            with tifffile.TiffFile(f) as tif:
                if len(tif.pages) != 1:
                    raise RecordingError(f"{label}: a TIFF with {len(tif.pages)} pages in a "
                                         "folder of single frames; pass the file itself")
                img = tif.pages[0].asarray()
                order = "RGB"  # TIFF's
        except RecordingError:
            raise
        except Exception as exc:
            img = _cv2_read(f)  # e.g. LZW compression without the imagecodecs package
            if img is None:
                raise RecordingError(f"{label} is unreadable: {exc}") from None
    else:
        img = _cv2_read(f)
        if img is None:
            raise RecordingError(f"{label} is unreadable (not a valid image file)")
    colour = img.ndim == 3 and img.shape[-1] in (3, 4)
    img = _grey(img, label, order)
    _check_sample_type(img.dtype, label)
    if dtype is not None and img.dtype != dtype:
        raise RecordingError(f"{label} has dtype {img.dtype}; frame 0 has {dtype}; all frames "
                             "must match")
    if shape is not None and img.shape != shape:
        raise RecordingError(f"{label} has size {img.shape[1]}x{img.shape[0]} px (WxH); frame 0 "
                             f"has {shape[1]}x{shape[0]} px; all frames must match")
    return img, colour


def _read_folder(p: Path) -> Recording:
    files = [f for f in p.iterdir() if f.is_file() and not f.name.startswith(".")]
    stacks = [f for f in files if f.suffix.lower() == ".npy"]
    images = sorted((f for f in files if f.suffix.lower() in FRAME_SUFFIXES),
                    key=lambda f: natural_key(f.name))
    if not images and len(stacks) == 1:
        return _read_npy(stacks[0], mmap=True)
    if not images:
        raise RecordingError(f"folder '{p}' holds no frames (expected {', '.join(FRAME_SUFFIXES)}"
                             " files or one .npy stack)")
    if len(images) == 1 and images[0].suffix.lower() in TIFF_SUFFIXES:
        return _read_tiff(images[0])  # a single (possibly multi-page) TIFF: the stack itself
    _check_numbering(p, images)
    first, colour = _read_single_frame(images[0], 0, None)
    frames = np.empty((len(images),) + first.shape, dtype=first.dtype)
    frames[0] = first
    for i, f in enumerate(images[1:], start=1):
        frames[i], colour_i = _read_single_frame(f, i, first.shape, first.dtype)
        colour = colour or colour_i
    frames, note = _convert(frames, was_colour=colour)
    return Recording(frames, f"folder of {len(images)} frames {p}{note}",
                     [f.name for f in images])


def _check_numbering(p: Path, images: list[Path]) -> None:
    """If the frames are numbered (``<prefix><number><suffix>``), the numbers must be consecutive.

    A gap means a frame is missing, which would silently shift the time base of every later
    frame; a repeated number means two files claim the same frame.
    """
    if len(images) < 2:
        return
    # one frame order: one naming pattern (digits aside), no two names of the same number
    patterns: dict[str, str] = {}
    for f in images:
        patterns.setdefault(re.sub(r"\d+", "#", f.name.lower()), f.name)
    if len(patterns) > 1:
        a, b = list(patterns.values())[:2]
        raise RecordingError(f"folder '{p}': the file names do not define one frame order "
                             f"('{a}' and '{b}' follow different patterns); expected one "
                             "numbered series of frames (and no other images) in the folder")
    keys = [natural_key(f.name) for f in images]
    for i in range(1, len(images)):
        if keys[i] == keys[i - 1]:
            raise RecordingError(f"folder '{p}': '{images[i - 1].name}' and '{images[i].name}' "
                                 "both claim the same place in the frame order (numbers "
                                 "written with and without leading zeros?)")
    parsed = [re.fullmatch(r"(.*?)(\d+)(\D*)", f.name) for f in images]
    if not all(parsed):
        return
    stems = {(m.group(1), m.group(3).lower()) for m in parsed}
    if len(stems) != 1:
        return  # not one numbered series: keep the natural order only
    numbers = [int(m.group(2)) for m in parsed]
    for i in range(1, len(numbers)):
        if numbers[i] == numbers[i - 1]:
            raise RecordingError(f"folder '{p}': '{images[i - 1].name}' and '{images[i].name}' "
                                 f"both claim frame number {numbers[i]}")
        if numbers[i] != numbers[i - 1] + 1:
            missing = numbers[i - 1] + 1
            raise RecordingError(
                f"folder '{p}': frame number {missing} is missing (between '{images[i - 1].name}'"
                f" and '{images[i].name}'); frames must be numbered consecutively")


def _read_video(p: Path) -> Recording:
    import cv2

    cap = cv2.VideoCapture(str(p))
    try:
        if not cap.isOpened():
            raise RecordingError(
                f"cannot read '{p}': not a folder of frames, a multi-page TIFF, a .npy stack or a "
                "video file OpenCV can decode")
        fps = cap.get(cv2.CAP_PROP_FPS)
        codec = fourcc_text(cap.get(cv2.CAP_PROP_FOURCC))
        frames = []
        while True:
            ok, img = cap.read()
            if not ok:
                break
            if img.ndim == 3:
                img = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
            if img.dtype != np.uint8:
                raise RecordingError(f"video '{p}', frame {len(frames)}: dtype {img.dtype}; "
                                     "expected 8 bits per pixel")
            if frames and img.shape != frames[0].shape:
                raise RecordingError(f"video '{p}', frame {len(frames)}: size {img.shape} differs "
                                     f"from frame 0 ({frames[0].shape})")
            frames.append(img)
    finally:
        cap.release()
    if not frames:
        raise RecordingError(f"video '{p}' holds no readable frames")
    # The container's rate is a playback rate for a high-speed camera's export, not the
    # recording's: reported, never used (measurement.imaging.frame_rate explains).
    known = bool(np.isfinite(fps) and fps > 0)
    return Recording(np.stack(frames), f"video {p} (converted to grayscale)",
                     fps_source="none: a video container states only a playback rate",
                     container_fps_hz=float(fps) if known else None,
                     codec=codec)
