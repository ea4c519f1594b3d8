"""HDR video's transfer functions: frames whose integer samples code light with SMPTE ST 2084 (PQ, HDR10) or
ARIB STD-B67 (HLG) are filtered in the linear light they code.

The filter's mix space for integer frames is the sRGB decode of the samples. PQ and HLG code light by other
curves (PQ: absolute luminance up to 10000 cd/m2; HLG: a square root below and a logarithm above), so a coverage
mix of their codes through the sRGB decode is not a coverage mix of light: an edge between a highlight and a
shadow came out darker than the truth (docs/spatial_tuning.md "HDR video"). Here the filter's decode and encode
tables (with_transfer_tables) are the transfer's: its passes mix light relative to BT.2408's reference white (203
cd/m2 for PQ; the HLG signal 0.75) and code the mix back, on the device, the frame staying in its codes. The edge
tests (CIELAB of the codes through the sRGB decode, Filter's `_lin_lab`) and the render-region statistics still read
the codes as they read any integer frame: a linear-light CIELAB clips at display white, and would not see the edges
between two highlights (a lamp on a lit wall) that the codes show.
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np

TRANSFERS = ("pq", "hlg")
TRANSFER_CHOICES = ("auto", *TRANSFERS, "sdr")   # --transfer: read from the file's tags, said, or none
TRANSFER_NAMES = {"pq": "SMPTE ST 2084 (PQ, HDR10)", "hlg": "ARIB STD-B67 (HLG)"}
# FFmpeg's AVColorTransferCharacteristic values (a video's color_trc; H.273's, as in a PNG's cICP) of the transfers
FFMPEG_TRC = {16: "pq", 18: "hlg"}
TRC_OF = {name: code for code, name in FFMPEG_TRC.items()}

# SMPTE ST 2084's constants (the PQ EOTF and its inverse)
_M1, _M2 = 2610.0 / 16384.0, 2523.0 / 4096.0 * 128.0
_C1, _C2, _C3 = 3424.0 / 4096.0, 2413.0 / 4096.0 * 32.0, 2392.0 / 4096.0 * 32.0
PQ_PEAK_NITS = 10000.0
REFERENCE_WHITE_NITS = 203.0  # ITU-R BT.2408: HDR reference (graphics) white; linear 1.0 here
# ARIB STD-B67 / BT.2100 HLG OETF constants
_HLG_A = 0.17883277
_HLG_B = 1.0 - 4.0 * _HLG_A
_HLG_C = 0.5 - _HLG_A * np.log(4.0 * _HLG_A)
HLG_REFERENCE_SIGNAL = 0.75  # BT.2408: HLG reference white's signal level; linear 1.0 here


def pq_to_linear(v: np.ndarray) -> np.ndarray:
    """PQ signal (0..1) -> light relative to reference white (ST 2084 EOTF; 10000 cd/m2 = 49.3), float64."""
    e = np.clip(np.asarray(v, np.float64), 0.0, 1.0) ** (1.0 / _M2)
    y = (np.maximum(e - _C1, 0.0) / (_C2 - _C3 * e)) ** (1.0 / _M1)
    return y * (PQ_PEAK_NITS / REFERENCE_WHITE_NITS)


def _float(x: np.ndarray) -> tuple[np.ndarray, type]:
    """`x` as float64 if it is, else float32 (~15x faster for pow here, within a 16-bit code), and that type."""
    f = np.float64 if np.asarray(x).dtype == np.float64 else np.float32
    return np.asarray(x, f), f


def linear_to_pq(lin: np.ndarray) -> np.ndarray:
    """Light relative to reference white -> PQ signal (0..1) (the inverse EOTF), in lin's float type (float32: 16-bit
    codes within one of the exact ones)."""
    lin, f = _float(lin)
    y = np.clip(lin * f(REFERENCE_WHITE_NITS / PQ_PEAK_NITS), 0.0, 1.0) ** f(_M1)
    return ((f(_C1) + f(_C2) * y) / (f(1.0) + f(_C3) * y)) ** f(_M2)


def _hlg_scene(v: np.ndarray) -> np.ndarray:
    """HLG signal (0..1) -> normalised scene light E (0..1): the inverse OETF of BT.2100, float64."""
    v = np.clip(np.asarray(v, np.float64), 0.0, 1.0)
    return np.where(v <= 0.5, v * v / 3.0, (np.exp((v - _HLG_C) / _HLG_A) + _HLG_B) / 12.0)


_HLG_WHITE = float(_hlg_scene(HLG_REFERENCE_SIGNAL))  # 0.2647: E of reference white


def hlg_to_linear(v: np.ndarray) -> np.ndarray:
    """HLG signal (0..1) -> scene light relative to reference white (the signal 0.75 = 1.0; peak 3.78), float64."""
    return _hlg_scene(v) / _HLG_WHITE


def linear_to_hlg(lin: np.ndarray) -> np.ndarray:
    """Scene light relative to reference white -> HLG signal (0..1) (BT.2100's OETF), in lin's float type."""
    lin, f = _float(lin)
    e = np.clip(lin * f(_HLG_WHITE), 0.0, 1.0)
    high = f(_HLG_A) * np.log(np.maximum(f(12.0) * e - f(_HLG_B), f(1e-30))) + f(_HLG_C)  # used above 1/12 only
    return np.where(e <= f(1.0 / 12.0), np.sqrt(f(3.0) * e), high).astype(f)


_DECODE = {"pq": pq_to_linear, "hlg": hlg_to_linear}
_ENCODE = {"pq": linear_to_pq, "hlg": linear_to_hlg}


def check_transfer(transfer: str | None) -> str | None:
    """`transfer` if it is None or one of TRANSFERS, else ValueError."""
    if transfer is not None and transfer not in TRANSFERS:
        raise ValueError(f"transfer: expected None or one of {', '.join(TRANSFERS)}, got {transfer!r}")
    return transfer


def _peak(transfer: str) -> float:
    """The transfer's largest light, relative to reference white (PQ 49.3, HLG 3.78)."""
    return PQ_PEAK_NITS / REFERENCE_WHITE_NITS if transfer == "pq" else 1.0 / _HLG_WHITE


def kernel_defines(transfer: str | None) -> dict:
    """Build defines for the filter's passes: the encode table's argument (common.cl encode_arg)."""
    return {} if transfer is None else {"ENCODE_WARP": 1, "ENCODE_SCALE": float(1.0 / _peak(transfer))}


def encode_arg(v: np.ndarray, transfer: str | None) -> np.ndarray:
    """common.cl's encode_arg in float32 numpy (the references' twin): `v` itself without a transfer, else
    (v ENCODE_SCALE)^(1/4), 0 for v <= 0 and NaN."""
    v = np.asarray(v, np.float32)
    if transfer is None:
        return v
    s = v * np.float32(kernel_defines(transfer)["ENCODE_SCALE"])
    with np.errstate(invalid="ignore"):
        pos = s > 0
    return np.where(pos, np.sqrt(np.sqrt(np.where(pos, s, np.float32(1)))), np.float32(0)).astype(np.float32)


def with_transfer_tables(luts: np.ndarray, transfer: str | None) -> np.ndarray:
    """The filter's tables (device.colour.device_luts: decode, CIELAB f, encode) with the decode (code / top ->
    light relative to reference white) and the encode (the signal of u^4 x the peak over u in [0, 1], read through
    common.cl's encode_arg) of `transfer` in place of sRGB's; `luts` itself for None."""
    if transfer is None:
        return luts
    n = luts.size // 3
    x = np.linspace(0.0, 1.0, n)
    out = luts.copy()
    out[:n] = _DECODE[transfer](x).astype(np.float32)
    out[2 * n:] = _ENCODE[transfer](x ** 4 * _peak(transfer)).astype(np.float32)
    return out


def encode(linear: np.ndarray, transfer: str) -> np.ndarray:
    """Light relative to reference white -> the transfer's signal (0..1), in linear's float type."""
    return _ENCODE[transfer](linear)


@lru_cache(maxsize=None)
def decode_table(transfer: str, top: int) -> np.ndarray:
    """Linear light of every code 0 .. top (uint8, uint16), float32: made once per transfer and sample type."""
    table = _DECODE[transfer](np.arange(top + 1) / top).astype(np.float32)
    table.setflags(write=False)
    return table
