"""How much a lossy recording changes the detector's boxes: the detector on a bag's lossless (PNG) camera
frames, and on the same frames through JPEG at several settings (docs/ros2.md, known limits).

    ocslam run --headless --route tour --duration 40 --record /tmp/bag_png --set replay.record_image_format=png
    python scripts/jpeg_detections.py /tmp/bag_png
"""
import argparse
from pathlib import Path

import cv2
import numpy as np
from rosbags.highlevel import AnyReader

from app.config import Config
from app.ocslam.detector import Detector
from app.ocslam.messages import Image

SETTINGS = {
    "q95 4:2:0": [cv2.IMWRITE_JPEG_QUALITY, 95],
    "q95 4:4:4": [cv2.IMWRITE_JPEG_QUALITY, 95, cv2.IMWRITE_JPEG_SAMPLING_FACTOR, cv2.IMWRITE_JPEG_SAMPLING_FACTOR_444],
    "q100 4:4:4": [cv2.IMWRITE_JPEG_QUALITY, 100, cv2.IMWRITE_JPEG_SAMPLING_FACTOR, cv2.IMWRITE_JPEG_SAMPLING_FACTOR_444],
}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("bag", type=Path, help="a bag recorded with replay.record_image_format=png")
    a = ap.parse_args()
    det = Detector(Config().detector)
    frames = []
    with AnyReader([a.bag]) as r:
        cons = [c for c in r.connections if c.topic == "/camera/image_raw/compressed"]
        for c, _t, raw in r.messages(connections=cons):
            m = r.deserialize(raw, c.msgtype)
            if "png" not in m.format:
                raise SystemExit(f"{a.bag}: its frames are {m.format!r}, not lossless PNG")
            frames.append(cv2.imdecode(np.frombuffer(m.data, np.uint8), cv2.IMREAD_COLOR))  # BGR

    def boxes(bgr: np.ndarray):
        return det.detect(Image(0.0, cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB))).boxes

    base = [boxes(f) for f in frames]
    print(f"{len(frames)} frames; the same frames again give the same boxes: {[boxes(f) for f in frames] == base}")
    for name, params in SETTINGS.items():
        other, px, size = 0, [0.0], 0
        for f, b0 in zip(frames, base):
            ok, buf = cv2.imencode(".jpg", f, params)
            size += len(buf)
            b1 = boxes(cv2.imdecode(buf, cv2.IMREAD_COLOR))
            if [d.class_id for d in b1] != [d.class_id for d in b0]:
                other += 1
                continue
            px += [max(abs(p.x1 - q.x1), abs(p.y1 - q.y1), abs(p.x2 - q.x2), abs(p.y2 - q.y2)) for p, q in zip(b0, b1)]
        print(f"JPEG {name}: {size / len(frames) / 1e3:.1f} kB a frame; frames with other boxes {other}/{len(frames)}; "
              f"box corners up to {max(px):.1f} px off")


if __name__ == "__main__":
    main()
