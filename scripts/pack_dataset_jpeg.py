"""Pack ``ocslam dataset`` folders small enough to carry to a machine that cannot render them.

A lent GPU machine has torch but neither pybullet nor a package registry, and takes a 64 MiB working
tree: its training data must travel. Each image is resized to the training width exactly as ultralytics
resizes it when it loads and caches an image for ``imgsz`` (``cv2.INTER_LINEAR``, long side to the
width), so the network sees the same pixels, then stored as JPEG (the only loss: quality 80 costs a mean
absolute error of about 3 grey levels, most of it the renders' own sensor noise). Labels (normalised) and
``data.yaml`` (with a ``packed`` note in its ``ocslam`` block) are copied unchanged.

    python scripts/pack_dataset_jpeg.py datasets/sim datasets/sim2-families --out .gpu --width 224 --quality 80
"""

from __future__ import annotations

import argparse
import shutil
from pathlib import Path

import cv2
import yaml


def pack(src: Path, out: Path, width: int, quality: int) -> tuple[int, int]:
    """``src`` → ``out`` (images as JPEG at ``width``). Returns (images, bytes of images written)."""
    n = size = 0
    for img in sorted(src.glob("images/*/*.png")):
        rel = img.relative_to(src)
        a = cv2.imread(str(img), cv2.IMREAD_COLOR)
        if a is None:
            raise SystemExit(f"pack: unreadable image {img}")
        h, w = a.shape[:2]
        r = width / max(h, w)
        if r < 1.0:
            a = cv2.resize(a, (round(w * r), round(h * r)), interpolation=cv2.INTER_LINEAR)
        ok, buf = cv2.imencode(".jpg", a, [cv2.IMWRITE_JPEG_QUALITY, quality])
        dst = (out / rel).with_suffix(".jpg")
        dst.parent.mkdir(parents=True, exist_ok=True)
        dst.write_bytes(buf.tobytes())
        n += 1
        size += len(buf)
    for lab in sorted(src.glob("labels/*/*.txt")):
        dst = out / lab.relative_to(src)
        dst.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(lab, dst)
    meta = yaml.safe_load((src / "data.yaml").read_text())
    meta.setdefault("ocslam", {})["packed"] = f"JPEG quality {quality}, {width} px wide (scripts/pack_dataset_jpeg.py)"
    (out / "data.yaml").write_text(f"# {src} packed for carrying\n" + yaml.safe_dump(meta, sort_keys=False))
    return n, size


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("datasets", type=Path, nargs="+")
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--width", type=int, default=224, help="the training imgsz (long side)")
    ap.add_argument("--quality", type=int, default=80)
    a = ap.parse_args()
    for d in a.datasets:
        n, size = pack(d, a.out / d.name, a.width, a.quality)
        print(f"{d} → {a.out / d.name}: {n} images, {size / 1e6:.1f} MB")


if __name__ == "__main__":
    main()
