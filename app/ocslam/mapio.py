"""Occupancy maps as map_server / Nav2 files: a YAML description plus a PGM image.

Conventions (``nav2_map_server``, ``mode: trinary``, ``negate: 0``):

- ``image``: the PGM file name, relative to the YAML file.
- ``resolution``: metres per pixel; ``origin``: ``[x, y, yaw]`` of the lower-left pixel's corner in ``map``.
- Pixel values: ``p = (255 − v) / 255`` is the occupancy probability; ``p > occupied_thresh`` (0.65) is
  occupied (written as 0, black), ``p < free_thresh`` (0.196) free (254, white), anything else unknown (205).
- Image row 0 is the *top* of the map, so rows are flipped relative to
  :class:`~app.ocslam.messages.OccupancyGrid` (whose row 0 is at the origin, the bottom).

Loading gives ``100`` / ``0`` / ``-1`` cells (trinary). Writes are atomic: each file is written to a
temporary name beside its target and renamed over it, the PGM first, so a reader never sees a YAML
that points at a half-written image. Failures raise :class:`MapIOError` saying what went wrong.
"""

from __future__ import annotations

import math
import os
import tempfile
from pathlib import Path

import numpy as np
import yaml

from app.ocslam.messages import OccupancyGrid
from app.ocslam.se2 import Pose2

OCCUPIED_THRESH = 0.65
FREE_THRESH = 0.196


class MapIOError(OSError):
    """A map could not be saved or loaded; the message says which file and why."""


_UMASK = os.umask(0)
os.umask(_UMASK)


def _atomic_write(path: Path, data: bytes) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        os.chmod(tmp, 0o666 & ~_UMASK)  # mkstemp creates 0600; the usual mode, like every other file
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise


def grid_to_pgm_pixels(grid: OccupancyGrid) -> np.ndarray:
    """``(H, W)`` uint8 trinary pixels (0 occupied, 254 free, 205 unknown), row 0 at the top."""
    d = np.asarray(grid.data)
    p = d.astype(np.float64) / 100.0
    img = np.full(d.shape, 205, np.uint8)
    known = d >= 0
    img[known & (p > OCCUPIED_THRESH)] = 0
    img[known & (p < FREE_THRESH)] = 254
    return np.flipud(img)


def encode_pgm(img: np.ndarray) -> bytes:
    """Binary (P5) PGM bytes of a ``(H, W)`` uint8 image."""
    h, w = img.shape
    return f"P5\n{w} {h}\n255\n".encode("ascii") + np.ascontiguousarray(img, np.uint8).tobytes()


def decode_pgm(data: bytes, name: str = "PGM") -> np.ndarray:
    """``(H, W)`` uint8 image from P5 (binary) or P2 (ASCII) PGM bytes (8-bit)."""
    tokens: list[bytes] = []
    pos = 0
    n = len(data)
    while len(tokens) < 4:
        while pos < n and data[pos : pos + 1].isspace():
            pos += 1
        if pos < n and data[pos : pos + 1] == b"#":
            while pos < n and data[pos : pos + 1] not in (b"\n", b"\r"):
                pos += 1
            continue
        start = pos
        while pos < n and not data[pos : pos + 1].isspace():
            pos += 1
        if start == pos:
            raise MapIOError(f"{name}: truncated PGM header")
        tokens.append(data[start:pos])
    magic = tokens[0]
    try:
        w, h, maxval = int(tokens[1]), int(tokens[2]), int(tokens[3])
    except ValueError:
        raise MapIOError(f"{name}: malformed PGM header") from None
    if w <= 0 or h <= 0 or not 0 < maxval < 256:
        raise MapIOError(f"{name}: unsupported PGM size {w}x{h} or maxval {maxval} (8-bit only)")
    if magic == b"P5":
        body = data[pos + 1 : pos + 1 + w * h]
        if len(body) != w * h:
            raise MapIOError(f"{name}: PGM has {len(body)} bytes of pixels, expected {w * h}")
        img = np.frombuffer(body, np.uint8).reshape(h, w)
    elif magic == b"P2":
        vals = data[pos:].split()
        if len(vals) < w * h:
            raise MapIOError(f"{name}: PGM has {len(vals)} pixels, expected {w * h}")
        img = np.array([int(v) for v in vals[: w * h]], np.int64).reshape(h, w).astype(np.uint8)
    else:
        raise MapIOError(f"{name}: not a PGM file (magic {magic[:2]!r})")
    if maxval != 255:
        img = np.round(img.astype(np.float64) * 255.0 / maxval).astype(np.uint8)
    return img


def save_map(grid: OccupancyGrid, yaml_path: str | os.PathLike[str], image_name: str | None = None) -> Path:
    """Save ``grid`` as ``yaml_path`` + a PGM beside it (default: same stem, ``.pgm``). Returns the YAML path.

    The grid's origin may be rotated (map_server supports a yaw in ``origin``).
    """
    yp = Path(yaml_path)
    if yp.suffix.lower() not in (".yaml", ".yml"):
        yp = yp.with_suffix(".yaml")
    img_name = image_name or (yp.stem + ".pgm")
    ip = yp.parent / img_name
    meta = {
        "image": img_name,
        "mode": "trinary",
        "resolution": float(grid.resolution),
        "origin": [float(grid.origin.x), float(grid.origin.y), float(grid.origin.yaw)],
        "negate": 0,
        "occupied_thresh": OCCUPIED_THRESH,
        "free_thresh": FREE_THRESH,
    }
    try:
        _atomic_write(ip, encode_pgm(grid_to_pgm_pixels(grid)))
        _atomic_write(yp, yaml.safe_dump(meta, sort_keys=False).encode("utf-8"))
    except OSError as e:
        raise MapIOError(f"cannot save map to {yp}: {e.strerror or e}") from e
    return yp


def load_map(yaml_path: str | os.PathLike[str]) -> OccupancyGrid:
    """Load a map_server YAML + image back into an :class:`OccupancyGrid` (100 / 0 / -1 cells)."""
    yp = Path(yaml_path)
    try:
        meta = yaml.safe_load(yp.read_text())
    except OSError as e:
        raise MapIOError(f"cannot read map {yp}: {e.strerror or e}") from e
    except yaml.YAMLError as e:
        raise MapIOError(f"{yp}: invalid YAML ({e})") from e
    if not isinstance(meta, dict):
        raise MapIOError(f"{yp}: expected a mapping")
    for key in ("image", "resolution", "origin"):
        if key not in meta:
            raise MapIOError(f"{yp}: missing '{key}'")
    try:
        res = float(meta["resolution"])
        origin = [float(v) for v in meta["origin"]]
        occ_t = float(meta.get("occupied_thresh", OCCUPIED_THRESH))
        free_t = float(meta.get("free_thresh", FREE_THRESH))
        negate = int(meta.get("negate", 0))
    except (TypeError, ValueError) as e:
        raise MapIOError(f"{yp}: bad numeric field ({e})") from e
    if not (res > 0 and math.isfinite(res)) or len(origin) != 3:
        raise MapIOError(f"{yp}: resolution must be > 0 and origin [x, y, yaw]")
    mode = str(meta.get("mode", "trinary"))
    if mode not in ("trinary", "scale", "raw"):
        raise MapIOError(f"{yp}: unknown mode {mode!r}")
    ip = Path(meta["image"])
    if not ip.is_absolute():
        ip = yp.parent / ip
    try:
        data = ip.read_bytes()
    except OSError as e:
        raise MapIOError(f"cannot read map image {ip}: {e.strerror or e}") from e
    if ip.suffix.lower() == ".pgm":
        img = decode_pgm(data, str(ip))
    else:
        import cv2

        decoded = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_GRAYSCALE)
        if decoded is None:
            raise MapIOError(f"{ip}: unreadable image")
        img = decoded
    v = img.astype(np.float64)
    p = v / 255.0 if negate else (255.0 - v) / 255.0
    if mode == "raw":
        out = np.clip(img.astype(np.int64), -1, 100).astype(np.int8)
    else:
        out = np.full(img.shape, -1, np.int8)
        out[p > occ_t] = 100
        out[p < free_t] = 0
        if mode == "scale":
            mid = (p >= free_t) & (p <= occ_t)
            out[mid] = np.rint(99 * (p[mid] - free_t) / (occ_t - free_t)).astype(np.int8)
    return OccupancyGrid(resolution=res, origin=Pose2(*origin), data=np.flipud(out).copy())
