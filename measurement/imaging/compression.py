"""Lossy compression of a recording: detected from the container's codec and from the pixels.

The tracking noise model of the measurement (independent sensor noise per pixel and frame, a
smooth lighting leftover) does not hold for frames that went through a lossy codec: JPEG and
the MPEG family quantise the DCT coefficients of 8x8 blocks (block edges, noise removed inside
the blocks, marker edges moved by up to a pixel in a way that depends on the block grid) and
inter-frame codecs copy blocks from earlier frames (a marker that stands still for a few
frames in the file moved in the scene). Neither is covered by the stated confidence, so such a
recording is named in ``status`` (:func:`lossy_status`).

Evidence, any of:

* the container's codec (OpenCV ``CAP_PROP_FOURCC``) is a known lossy one (:data:`LOSSY_FOURCC`);
* **block edges**: the mean absolute difference between horizontally (vertically) adjacent
  pixels, per column (row) phase modulo 8, peaks at the block boundary; a lossless recording
  has the same statistic at every phase (:func:`block_edge_ratio`);
* **frozen blocks**: 8x8 blocks that are bit-identical in consecutive frames although the frame
  carries sensor noise (:func:`frozen_block_share`); sensor noise never repeats exactly.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: FourCC codes of lossy video codecs (upper case; OpenCV/FFmpeg spellings).
LOSSY_FOURCC = frozenset({
    "MJPG", "JPEG", "MP4V", "FMP4", "XVID", "DIVX", "DX50", "MP42", "MP43", "H264", "AVC1",
    "X264", "HEVC", "HVC1", "HEV1", "H265", "X265", "VP80", "VP90", "VP09", "AV01", "WMV1",
    "WMV2", "WMV3", "WVC1", "MPG1", "MPG2", "MPEG", "PIM1", "THEO", "DVSD", "MP2V", "M4S2",
    "3IV2", "FLV1", "H263", "U263", "S263", "MJ2C", "CVID", "IV50", "IV41", "IV32",
})
#: Block-edge ratio above which a recording is called block-coded (lossless twin frames: 1.02-1.04,
#: the max of 8 phases; their mp4v / MJPG / XVID: 1.18-1.47, tests/test_compression.py).
BLOCK_EDGE_LIMIT = 1.10
#: Share of frozen 8x8 blocks (between noisy frames) above which inter-frame coding is called.
FROZEN_LIMIT = 0.02
#: Sensor noise [DN] below which frozen blocks prove nothing (a noise-free render repeats; the
#: 8-bit steps of a smooth gradient alone read as ~0.6 DN).
NOISE_FLOOR_DN = 1.0
#: Frames sampled for the pixel statistics (spread over the recording).
SAMPLE_FRAMES = 12


@dataclass(frozen=True)
class Compression:
    """What was found; ``lossy`` if any evidence holds."""

    codec: str | None             #: the container's FourCC, or None (not a video / unknown)
    codec_lossy: bool
    block_edge_ratio: float       #: largest of the horizontal and vertical ratios [1]
    frozen_block_share: float     #: share of 8x8 blocks unchanged between frames [1]
    noise_dn: float               #: sensor noise estimate [DN]

    @property
    def block_coded(self) -> bool:
        return self.block_edge_ratio > BLOCK_EDGE_LIMIT

    @property
    def inter_frame(self) -> bool:
        return self.noise_dn > NOISE_FLOOR_DN and self.frozen_block_share > FROZEN_LIMIT

    @property
    def lossy(self) -> bool:
        return self.codec_lossy or self.block_coded or self.inter_frame

    def evidence(self) -> str:
        parts = []
        if self.codec is not None:
            parts.append(f"codec '{self.codec}'" + (" (lossy)" if self.codec_lossy else ""))
        if self.block_coded:
            parts.append(f"8x8 block edges {self.block_edge_ratio:.2f}x the in-block "
                         "pixel differences")
        if self.inter_frame:
            parts.append(f"{100 * self.frozen_block_share:.0f} % of 8x8 blocks frozen between "
                         "frames")
        return ", ".join(parts)

    def summary(self) -> dict:
        return {"lossy": self.lossy, "evidence": self.evidence(), "codec": self.codec, "codec_lossy": self.codec_lossy,
                "block_edge_ratio": self.block_edge_ratio,
                "block_edge_limit": BLOCK_EDGE_LIMIT,
                "frozen_block_share": self.frozen_block_share,
                "frozen_block_limit": FROZEN_LIMIT, "noise_dn": self.noise_dn}


def fourcc_text(code: float | int | None) -> str | None:
    """The FourCC string of OpenCV's ``CAP_PROP_FOURCC`` value (None for 0 / unknown)."""
    if code is None or not np.isfinite(code) or int(code) <= 0:
        return None
    text = int(code).to_bytes(4, "little").decode("latin-1").strip("\x00 ")
    return text if text.isprintable() and text else None


def _phase_ratio(diff: np.ndarray, axis: int) -> float:
    """Largest mean |difference| at one phase modulo 8 over the median of the others."""
    prof = diff.mean(axis=tuple(a for a in range(diff.ndim) if a != axis))
    n = prof.size - prof.size % 8
    if n < 16:
        return 1.0
    phase = prof[:n].reshape(-1, 8).mean(axis=0)
    k = int(np.argmax(phase))
    rest = np.median(np.delete(phase, k))
    return float(phase[k] / rest) if rest > 0 else 1.0


def _exact_ints(frames: np.ndarray) -> np.ndarray | None:
    """8- or 16-bit integer frames as a signed type their differences fit exactly, else None."""
    f = np.asarray(frames)
    if f.dtype.kind not in "ui" or f.dtype.itemsize > 2:
        return None
    return f.astype(np.int16 if f.dtype.itemsize == 1 else np.int32)


def _quantile(values: np.ndarray, q: float) -> float:
    """``np.quantile(values, q)`` (linear interpolation between order statistics); for
    non-negative integers from their histogram, O(n) where the partition of ~0.8 million
    values costs ~8 ms a call (a third of :func:`detect`)."""
    v = values.ravel()
    if v.dtype.kind == "f" or v.size == 0:
        return float(np.quantile(v, q))
    rank = np.cumsum(np.bincount(v))             # rank[k]: how many values are <= k
    pos = q * (v.size - 1)
    lo = int(np.floor(pos))
    a, b = np.searchsorted(rank, [lo, min(lo + 1, v.size - 1)], side="right")
    return float(a + (b - a) * (pos - lo))


def block_edge_ratio(frames: np.ndarray) -> float:
    """Block-boundary statistic of (n, H, W) frames [1]: 1 without 8x8 block coding."""
    f = _exact_ints(frames)
    if f is None:
        f = np.asarray(frames, np.float32)
    dx = np.abs(np.diff(f, axis=2))      # difference between columns c and c + 1
    dy = np.abs(np.diff(f, axis=1))
    # edges of the scene (markers, the CD's rim) are clipped: the statistic is the texture's
    cap = np.float32(max(_quantile(dx, 0.9), _quantile(dy, 0.9), 1.0))
    return max(_phase_ratio(np.minimum(dx, cap), 2), _phase_ratio(np.minimum(dy, cap), 1))


def noise_dn(frames: np.ndarray) -> float:
    """Sensor noise [DN] from the median absolute second difference along rows."""
    f = _exact_ints(frames)
    if f is None:
        f = np.asarray(frames, np.float32)
    d2 = f[:, :, 2:] - 2 * f[:, :, 1:-1] + f[:, :, :-2]
    return float(1.4826 * _quantile(np.abs(d2), 0.5) / np.sqrt(6.0))


def frozen_block_share(frames: np.ndarray) -> float:
    """Share of 8x8 blocks bit-identical between consecutive frames of ``frames`` [1]."""
    f = np.asarray(frames, np.int16)
    n, h, w = f.shape
    if n < 2 or h < 8 or w < 8:
        return 0.0
    d = np.abs(np.diff(f[:, : h - h % 8, : w - w % 8], axis=0))
    blocks = d.reshape(n - 1, h // 8, 8, w // 8, 8).max(axis=(2, 4))
    return float(np.mean(blocks == 0))


def detect(frames: np.ndarray, codec: str | None = None) -> Compression:
    """The evidence of lossy compression in a (N, H, W) uint8 recording."""
    n = int(frames.shape[0])
    starts = np.unique(np.linspace(0, max(n - 2, 0), min(SAMPLE_FRAMES // 2, n)).astype(int))
    sample = np.concatenate([np.asarray(frames[s: s + 2]) for s in starts])
    pairs = [np.asarray(frames[s: s + 2]) for s in starts if s + 2 <= n]
    frozen = float(np.mean([frozen_block_share(p) for p in pairs])) if pairs else 0.0
    lossy_codec = codec is not None and codec.upper() in LOSSY_FOURCC
    return Compression(codec, lossy_codec, block_edge_ratio(sample), frozen, noise_dn(sample))


def lossy_status(status: str, comp: dict | None) -> str:
    """``status`` naming the compression (``Compression.summary()``; unchanged when the
    recording is not lossy or nothing is known)."""
    if not comp or not comp.get("lossy"):
        return status
    note = (f"lossy compression ({comp['evidence']}): the interval assumes independent sensor "
            "noise and is not coverage-tested on compressed frames; record losslessly "
            "(raw, TIFF, PNG, FFV1)")
    return note if status == "ok" else f"{status}; {note}"
