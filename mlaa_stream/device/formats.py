"""Frame formats: which numpy frames we accept, and the one function that turns them into defines."""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from mlaa_stream.device.transfer import kernel_defines as transfer_defines

LUT_SIZE = 4096

_PIXEL_TYPES = {
    np.dtype(np.uint8): ("uchar", 255.0),
    np.dtype(np.uint16): ("ushort", 65535.0),
    np.dtype(np.float32): ("float", 1.0),
}


@dataclass(frozen=True)
class FrameFormat:
    """What the kernels need to know about a frame: size, channels, sample type, channel order, and the transfer
    its integer samples code light with where it is not sRGB (device/transfer.py: "pq", "hlg")."""

    height: int
    width: int
    channels: int
    dtype: np.dtype
    bgr: bool = False
    transfer: str | None = None

    @property
    def pixels(self) -> int:
        return self.height * self.width

    @property
    def nbytes(self) -> int:
        return self.pixels * self.channels * self.dtype.itemsize


def frame_format(frame: np.ndarray, bgr: bool = False, what: str = "frame") -> FrameFormat:
    """Check a frame on the host and describe it; errors read 'expected X, got Y'."""
    if not isinstance(frame, np.ndarray):
        raise TypeError(f"{what}: expected a numpy array, got {type(frame).__name__}")
    if frame.ndim == 2:
        channels = 1
    elif frame.ndim == 3 and frame.shape[2] in (1, 3, 4):
        channels = frame.shape[2]
    else:
        raise ValueError(f"{what}: expected shape (H, W) or (H, W, 1|3|4), got {frame.shape}")
    dtype = np.dtype(frame.dtype)
    if dtype == np.float16 or dtype == np.float64:
        dtype = np.dtype(np.float32)  # widened on upload; written back in the input's dtype
    if dtype not in _PIXEL_TYPES:
        # float64 is taken too (as float32): name it, and how to convert the rest (numpy arithmetic makes int64)
        hint = " (e.g. frame.clip(0, 255).astype(np.uint8))" if dtype.kind in "iub" else ""
        raise ValueError(f"{what}: expected uint8, uint16, float16, float32 or float64 samples, got {frame.dtype}"
                         f"{hint}")
    h, w = frame.shape[:2]
    if h < 1 or w < 1:
        raise ValueError(f"{what}: expected at least 1x1 pixels, got {w}x{h}")
    return FrameFormat(h, w, channels, dtype, bool(bgr) and channels >= 3)


def with_transfer(fmt: FrameFormat, transfer: str | None) -> FrameFormat:
    """`fmt` carrying `transfer` where its samples are integer codes (device/transfer.py); float frames hold light or
    sRGB-coded values, never a transfer's codes: `fmt` as it is."""
    return replace(fmt, transfer=transfer) if transfer is not None and fmt.dtype.kind in "ui" else fmt


def defines_for(fmt: FrameFormat, **options: object) -> dict[str, object]:
    """The one place where a frame format (and pass options) becomes OpenCL build defines."""
    ctype, pmax = _PIXEL_TYPES[fmt.dtype]
    d: dict[str, object] = {
        "PIXEL_T": ctype,
        "CHANNELS": fmt.channels,
        "PIXEL_MAX": float(pmax),
        "SAMPLE_BYTES": fmt.dtype.itemsize,
        "ORDER_BGR": int(fmt.bgr),
        "LUT_SIZE": LUT_SIZE,
    }
    if ctype == "float":
        d["PIXEL_IS_FLOAT"] = 1
    d.update(transfer_defines(fmt.transfer))
    d.update(options)
    return d


LUMA256 = np.array([54, 183, 19], np.int64)  # Rec. 709 luma in 256ths, on 8-bit levels (common.cl levels8)


def levels8(frame: np.ndarray, bgr: bool = False) -> np.ndarray:
    """(h, w, 3) int64 8-bit levels in R, G, B order of a uint8 / uint16 / float frame (floats clipped to [0, 1])."""
    fmt = frame_format(frame, bgr)
    a = np.asarray(frame).reshape(fmt.height, fmt.width, fmt.channels)
    a = np.repeat(a[..., :1], 3, -1) if fmt.channels == 1 else a[..., :3]
    if fmt.bgr and fmt.channels >= 3:
        a = a[..., ::-1]
    if a.dtype == np.uint8:
        return a.astype(np.int64)
    if a.dtype == np.uint16:
        return (a.astype(np.int64) * 255 + 32767) // 65535
    # NaN -> 0 and +-inf -> 1 / 0, as OpenCL's fmin / fmax clamp them in level8 (no cast of a NaN)
    f = np.clip(np.nan_to_num(a.astype(np.float32), nan=0.0, posinf=1.0, neginf=0.0), np.float32(0),
                np.float32(1)) * np.float32(255)
    return np.floor(f + np.float32(0.5)).astype(np.int64)
