"""Camera sample formats the tracker does not take directly, converted to 8-bit grey on reading.

High-speed cameras write 10-, 12- or 16-bit monochrome frames in 16-bit containers (TIFF, PNG)
and some write colour (RGB / BGR, with or without alpha). The tracker works on (N, H, W) uint8:

* colour -> grey with the ITU-R BT.601 luma weights (OpenCV's ``cvtColor`` weights);
* 16-bit -> 8-bit by the right shift that brings the recording's largest sample below 256
  (one shift for all frames: the frames keep one common intensity scale; a 12-bit camera's
  0..4095 loses its 4 lowest bits). The tracker's sub-pixel centres average hundreds of pixels
  per marker, so the 8-bit quantisation (1/sqrt(12) of a step) adds little to a camera's own
  noise; a camera with less noise than that would lose accuracy here.

What was converted is said in the recording's ``source`` text (and so in ``summary.json``).
"""
from __future__ import annotations

import numpy as np

#: Luma weights of R, G, B (ITU-R BT.601, as OpenCV's RGB2GRAY).
LUMA_RGB = (0.299, 0.587, 0.114)
#: Sample types accepted (converted to uint8 if not uint8).
SAMPLE_TYPES = (np.uint8, np.uint16)


#: Frames converted per block (bounds the float32 temporaries of a long colour recording).
BLOCK_FRAMES = 64


def luma(frames: np.ndarray, order: str = "RGB") -> np.ndarray:
    """Grey frames (same dtype) from colour frames (..., C), C = 3 or 4 (alpha ignored);
    ``order`` ``RGB`` (TIFF, NumPy) or ``BGR`` (OpenCV's imread)."""
    frames = np.asarray(frames)
    w = np.array(LUMA_RGB if order == "RGB" else LUMA_RGB[::-1], dtype=np.float32)
    top = np.iinfo(frames.dtype).max
    if frames.ndim < 4:
        return _luma_block(frames, w, top)
    out = np.empty(frames.shape[:-1], dtype=frames.dtype)
    for i in range(0, frames.shape[0], BLOCK_FRAMES):
        out[i:i + BLOCK_FRAMES] = _luma_block(frames[i:i + BLOCK_FRAMES], w, top)
    return out


def _luma_block(frames: np.ndarray, w: np.ndarray, top: int) -> np.ndarray:
    grey = frames[..., :3].astype(np.float32) @ w
    return np.clip(np.rint(grey), 0, top).astype(frames.dtype)


def to_uint8(frames: np.ndarray) -> tuple[np.ndarray, str | None]:
    """(uint8 frames, what was done or None) for uint8 or uint16 frames."""
    if frames.dtype == np.uint8:
        return frames, None  # as is (a memory map stays one)
    top = int(frames.max()) if frames.size else 0
    shift = max(0, top.bit_length() - 8)
    out = np.empty(frames.shape, dtype=np.uint8)
    for i in range(0, frames.shape[0], BLOCK_FRAMES):   # no full-size 16-bit temporary
        out[i:i + BLOCK_FRAMES] = frames[i:i + BLOCK_FRAMES] >> shift
    return out, f"16-bit samples (largest {top}) to 8 bits (right shift by {shift})"


def describe(colour: bool, depth_note: str | None) -> str:
    """The conversion text for a recording's source, '' if nothing was converted."""
    parts = (["colour to grey (BT.601 luma)"] if colour else []) + \
        ([depth_note] if depth_note else [])
    return f" (converted: {'; '.join(parts)})" if parts else ""
