"""The YOLO object detector, run with onnxruntime (no torch at runtime).

The paper's pipeline (spec §6): take the RGB camera image, downscale it to the network's input width
(224 px: a 640×480 image becomes 224×168, padded to the stride multiple 224×192), run YOLOv8-nano, keep
the boxes above the confidence threshold (40 %), and express them in original-image pixels as the
``/yolo_boxes`` matrix ``x1, y1, x2, y2, class, floor(conf·100)``.

The network's output is ultralytics' export layout ``[1, 4 + C, N]``: for each of N anchors the box
centre, width and height in input pixels (``cx, cy, w, h``) followed by C class scores (already
sigmoid-ed). Decoding keeps each anchor's best class, drops scores below the threshold, and runs
class-aware NMS with OpenCV (``cv2.dnn.NMSBoxesBatched``), which reproduces ultralytics' own
predictions on the same ONNX file.

Example:
    >>> det = Detector(DetectorConfig())                 # assets/models/detector.onnx
    >>> dets = det.detect(image)                          # Image (H, W, 3) RGB8
    >>> dets.yolo_boxes()                                 # (K, 6) int32, original-image pixels
    >>> overlay = draw_detections(image.data, dets)
"""

from __future__ import annotations

import ast
import hashlib
import math
import threading
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

from app.ocslam.calibration import ScoreCalibration
from app.ocslam.config import DetectorConfig
from app.ocslam.messages import CLASS_INDEX, CLASS_NAMES, Detection, Detections, Image

__all__ = [
    "Detector",
    "DetectorError",
    "Letterbox",
    "MAKE_MODEL_COMMAND",
    "find_model_card",
    "verify_model_hash",
    "CLASS_COLORS",
    "letterbox",
    "decode_output",
    "draw_detections",
]

#: How to (re)make the committed model; named in every "missing/corrupt model" error.
MAKE_MODEL_COMMAND = (
    "ocslam dataset --worlds 40 --per-world 45 --seed 1 --out datasets/sim && "
    "ocslam train-detector --data datasets/sim   (needs: pip install -e '.[train]'; see docs/detector.md)"
)

#: One RGB colour per class (CLASS_NAMES order), distinct and readable on camera images.
CLASS_COLORS: tuple[tuple[int, int, int], ...] = (
    (255, 64, 64),  # ball
    (255, 160, 32),  # dog
    (220, 220, 0),  # gnome
    (64, 200, 64),  # table
    (0, 200, 200),  # chair
    (64, 128, 255),  # door
    (255, 230, 120),  # duck
    (200, 64, 255),  # person
    (255, 0, 128),  # extinguisher
    (128, 255, 128),  # flowers
    (170, 120, 60),  # shelf
)

#: Ultralytics' letterbox padding value.
PAD_VALUE = 114
STRIDE = 32


class DetectorError(RuntimeError):
    """The model file is missing, corrupt or incompatible, or an input image is malformed."""


@dataclass(frozen=True, slots=True)
class Letterbox:
    """How an image was fitted into the network input: ``input = original · scale + (pad_x, pad_y)``."""

    scale: float
    pad_x: float
    pad_y: float
    input_width: int
    input_height: int


def input_shape_for(width: int, height: int, input_width: int, stride: int = STRIDE) -> tuple[int, int]:
    """Network input ``(width, height)`` for a dynamic model: ``input_width`` wide, the image's aspect,
    the height rounded up to the stride (the paper's 640×480 at 224 → 224×168 → 224×192)."""
    h = int(round(height * input_width / width))
    return input_width, int(math.ceil(h / stride) * stride)


def letterbox_geometry(width: int, height: int, input_width: int, input_height: int) -> tuple[Letterbox, int, int]:
    """How a ``width × height`` image fits ``input_width × input_height`` keeping its aspect (centred
    padding, as ultralytics does): the :class:`Letterbox` and the resized content size ``(nw, nh)``."""
    r = min(input_width / width, input_height / height)
    nw, nh = int(round(width * r)), int(round(height * r))
    dw, dh = (input_width - nw) / 2.0, (input_height - nh) / 2.0
    top, left = int(round(dh - 0.1)), int(round(dw - 0.1))
    return Letterbox(r, float(left), float(top), input_width, input_height), nw, nh


def letterbox(
    rgb: NDArray[np.uint8], input_width: int, input_height: int, out: NDArray[np.float32] | None = None
) -> tuple[NDArray[np.float32], Letterbox]:
    """Downscale ``(H, W, 3)`` uint8 RGB to fit ``input_width × input_height`` keeping its aspect, pad
    the rest with grey 114 (centred, as ultralytics does), and return the ``(1, 3, h, w)`` float32 NCHW
    tensor in [0, 1] with the :class:`Letterbox` that maps boxes back.

    ``out``: a ``(1, 3, input_height, input_width)`` float32 buffer whose padding already holds
    114/255 for this geometry (as left by an earlier call on an image of the same size); only the
    content is written (no allocation). Without it a new tensor is made."""
    h, w = rgb.shape[:2]
    lb, nw, nh = letterbox_geometry(w, h, input_width, input_height)
    if (nw, nh) != (w, h):
        interp = cv2.INTER_AREA if lb.scale < 1.0 else cv2.INTER_LINEAR
        resized = cv2.resize(rgb, (nw, nh), interpolation=interp)
    else:
        resized = rgb
    if out is None:
        out = np.full((1, 3, input_height, input_width), np.float32(PAD_VALUE / 255.0), np.float32)
    top, left = int(lb.pad_y), int(lb.pad_x)
    # HWC uint8 → CHW float32 in [0, 1], straight into the padded tensor.
    np.multiply(resized.transpose(2, 0, 1), np.float32(1.0 / 255.0), out=out[0, :, top : top + nh, left : left + nw])
    return out, lb


def decode_output(
    output: NDArray[np.floating],
    num_classes: int,
    confidence: float,
    nms_iou: float,
    lb: Letterbox,
    image_width: int,
    image_height: int,
    max_det: int = 300,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.int64]]:
    """Decode one YOLO output into boxes in original-image pixels.

    ``output`` is ``(1, 4 + C, N)`` or ``(4 + C, N)`` (``cx, cy, w, h`` in input pixels, then C class
    scores). Keeps each anchor's best class if its score ≥ ``confidence``, maps the boxes back through
    the letterbox, clips them to the image and applies class-aware NMS at ``nms_iou``.

    Returns ``(K, 4)`` ``x1, y1, x2, y2``, ``(K,)`` scores and ``(K,)`` class ids, best score first.
    """
    out = np.asarray(output)
    if out.ndim == 3:
        if out.shape[0] != 1:
            raise DetectorError(f"expected a batch of one image, got output shape {out.shape}")
        out = out[0]
    if out.ndim != 2 or out.shape[0] != 4 + num_classes:
        raise DetectorError(f"expected a [1, {4 + num_classes}, N] output, got {np.asarray(output).shape}")
    scores_all = out[4:]
    best = scores_all.max(axis=0)  # NaN propagates and fails the threshold below
    keep = np.flatnonzero((best >= confidence) & np.isfinite(best))
    if keep.size == 0:
        return np.zeros((0, 4)), np.zeros(0), np.zeros(0, dtype=np.int64)
    sel = out[:, keep]  # only the anchors above the threshold are decoded
    cls = np.argmax(sel[4:], axis=0).astype(np.int64)
    score = best[keep].astype(np.float64)
    cx, cy, bw, bh = (sel[i].astype(np.float64) for i in range(4))
    x1 = (cx - bw / 2.0 - lb.pad_x) / lb.scale
    y1 = (cy - bh / 2.0 - lb.pad_y) / lb.scale
    x2 = (cx + bw / 2.0 - lb.pad_x) / lb.scale
    y2 = (cy + bh / 2.0 - lb.pad_y) / lb.scale
    boxes = np.stack(
        [
            np.clip(x1, 0.0, image_width),
            np.clip(y1, 0.0, image_height),
            np.clip(x2, 0.0, image_width),
            np.clip(y2, 0.0, image_height),
        ],
        axis=1,
    )
    finite = np.all(np.isfinite(boxes), axis=1) & (boxes[:, 2] > boxes[:, 0]) & (boxes[:, 3] > boxes[:, 1])
    boxes, score, cls = boxes[finite], score[finite], cls[finite]
    if len(boxes) == 0:
        return np.zeros((0, 4)), np.zeros(0), np.zeros(0, dtype=np.int64)
    xywh = np.concatenate([boxes[:, :2], boxes[:, 2:] - boxes[:, :2]], axis=1)
    # cv2's stub lists only Sequence[Rect2d]; NMSBoxesBatched takes the (N, 4) array as it is
    kept = cv2.dnn.NMSBoxesBatched(
        xywh, score.astype(np.float32), cls.astype(np.int32), float(confidence), float(nms_iou)  # type: ignore[arg-type]
    )
    idx = np.asarray(kept, dtype=np.int64).reshape(-1)
    idx = idx[np.argsort(-score[idx], kind="stable")][:max_det]
    return boxes[idx], score[idx], cls[idx]


#: Where the committed models and their cards live (a model here must be described by a card).
MODELS_DIR = Path(__file__).resolve().parents[2] / "assets" / "models"


#: file_sha256's results by (path, size, modification time): a model is hashed once per process, however
#: often its card, its calibration or a sweep's recording key asks for it
_SHA256: dict[tuple[str, int, int], str] = {}
#: _read_card's parsed cards by (path, size, modification time) (None: not a mapping)
_CARDS: dict[tuple[str, int, int], dict | None] = {}


def file_sha256(path: Path) -> str:
    """Hex sha256 of a file's bytes (cached while the file's size and modification time stay the same)."""
    st = Path(path).stat()
    key = (str(Path(path).resolve()), st.st_size, st.st_mtime_ns)
    if key not in _SHA256:
        h = hashlib.sha256()
        with open(path, "rb") as f:
            for chunk in iter(lambda: f.read(1 << 20), b""):
                h.update(chunk)
        _SHA256[key] = h.hexdigest()
    return _SHA256[key]


def _card_entries(card: dict) -> list[dict]:
    """The model entries of a card: ``model`` and each of ``variants`` (dicts with ``file``, ``sha256``)."""
    entries = []
    if isinstance(card.get("model"), dict):
        entries.append(card["model"])
    variants = card.get("variants")
    if isinstance(variants, list):
        entries.extend(v for v in variants if isinstance(v, dict))
    return entries


def _read_card(path: Path) -> dict | None:
    """A model card's YAML as a dict (shared: read it, never change it), or None if unreadable or not a mapping;
    the parse is cached while the file's size and modification time stay the same (a sweep replays hundreds of
    traces)."""
    import yaml

    try:
        st = path.stat()
        key = (str(path.resolve()), st.st_size, st.st_mtime_ns)
        if key not in _CARDS:
            card = yaml.safe_load(path.read_text())
            _CARDS[key] = card if isinstance(card, dict) else None
    except (OSError, UnicodeDecodeError, yaml.YAMLError):
        return None
    return _CARDS[key]


def find_model_card(model: Path) -> tuple[Path, dict] | None:
    """The card that describes ``model`` and its entry (``file``, ``sha256``, ...), or None.

    Looks at ``<stem>.yaml`` beside the model first, then at every ``*.yaml`` in the model's folder, for
    a ``model`` or ``variants[]`` entry whose ``file`` is the model's file name. Unreadable YAML files
    are skipped (they describe nothing).
    """
    import copy

    model = Path(model)
    folder = model.parent
    first = model.with_suffix(".yaml")
    candidates = ([first] if first.is_file() else []) + sorted(p for p in folder.glob("*.yaml") if p != first)
    for card_path in candidates:
        card = _read_card(card_path)
        if card is None:
            continue
        for entry in _card_entries(card):
            if str(entry.get("file", "")) == model.name:
                return card_path, copy.deepcopy(entry)  # the caller's own: the parsed card is shared
    return None


def verify_model_hash(model: Path) -> str | None:
    """Check ``model``'s sha256 against its card; return the hash, or None if no card describes it.

    Raises :class:`DetectorError` (one line naming both hashes) on a mismatch, if the card's entry
    has no sha256, or if the model lies in the project's ``assets/models`` and no card there names it.
    """
    model = Path(model)
    found = find_model_card(model)
    if found is None:
        if model.resolve().parent == MODELS_DIR:
            raise DetectorError(
                f"detector model {model} is not described by any model card in {MODELS_DIR} "
                f"(add its sha256 to the card, or set detector.verify_hash: false)"
            )
        return None
    card_path, entry = found
    expected = str(entry.get("sha256") or "").strip().lower()
    actual = file_sha256(model)
    if not expected:
        raise DetectorError(
            f"model card {card_path} gives no sha256 for {model.name}; refusing {model} (sha256 {actual}); "
            f"set detector.verify_hash: false to load it anyway"
        )
    if actual != expected:
        raise DetectorError(
            f"detector model {model} does not match its card {card_path}: sha256 {actual}, card says {expected} "
            f"(the file was changed or replaced; re-make it with ocslam train-detector, or set detector.verify_hash: false)"
        )
    return actual


def model_score_calibration(model: Path) -> ScoreCalibration | None:
    """The Platt scaling of ``model``'s scores from its card (its entry's ``score_calibration``), or None
    when no card describes the file, the entry has none, or the file's sha256 is not the card's (a
    calibration fitted for other weights). Raises :class:`DetectorError` on a malformed entry."""
    found = find_model_card(Path(model))
    if found is None:
        return None
    card_path, entry = found
    if "score_calibration" not in entry:
        return None
    if str(entry.get("sha256") or "").strip().lower() != file_sha256(Path(model)):
        return None
    try:
        return ScoreCalibration.from_dict(entry["score_calibration"])
    except ValueError as e:
        raise DetectorError(f"model card {card_path}: {model.name}: {e}") from None


def detector_score_calibration(detector: object) -> ScoreCalibration:
    """The score calibration the object map applies to ``detector``'s boxes: a YOLO :class:`Detector`'s
    (its card's), the identity for the oracle, a custom detector or none."""
    cal = getattr(detector, "score_calibration", None)
    return cal if isinstance(cal, ScoreCalibration) else ScoreCalibration()


def _calibration_of(model: Path, calibration: str) -> ScoreCalibration:
    """``model``'s card calibration with ``detector.calibration: card`` (identity without one, or ``off``)."""
    if calibration != "card" or not model.is_file():
        return ScoreCalibration()
    return model_score_calibration(model) or ScoreCalibration()


def score_calibration_for(cfg: DetectorConfig) -> ScoreCalibration:
    """The score → probability map the object map uses with ``cfg``'s detector: the model card's for
    ``kind: yolo`` with ``calibration: card``, else the identity (the oracle's and the paper's scores)."""
    if cfg.kind != "yolo":
        return ScoreCalibration()
    return _calibration_of(_resolve(cfg.model_path), cfg.calibration)


def session_config_entries(cfg: DetectorConfig) -> dict[str, str]:
    """onnxruntime session config entries from the config: intra-op spin-waiting (``cfg.spin``; off by
    default: on the app's 2 shared cores a spinning thread takes the CPU the loop needs, measured in
    docs/detector.md) and flushing denormals to zero (``cfg.denormal_as_zero``)."""
    return {
        "session.intra_op.allow_spinning": "1" if getattr(cfg, "spin", False) else "0",
        "session.set_denormal_as_zero": "1" if getattr(cfg, "denormal_as_zero", False) else "0",
    }


def _parse_metadata(meta: dict[str, str]) -> tuple[tuple[str, ...] | None, int | None]:
    """Class names and training input width from ultralytics' ONNX metadata (``names``, ``imgsz``)."""
    names: tuple[str, ...] | None = None
    width: int | None = None
    try:
        if "names" in meta:
            d = ast.literal_eval(meta["names"])
            if isinstance(d, dict):
                names = tuple(str(d[k]) for k in sorted(d))
            elif isinstance(d, (list, tuple)):
                names = tuple(str(n) for n in d)
        if "imgsz" in meta:
            s = ast.literal_eval(meta["imgsz"])
            width = int(s[-1]) if isinstance(s, (list, tuple)) else int(s)
    except (ValueError, SyntaxError, TypeError, KeyError):
        pass
    return names, width


class Detector:
    """YOLO detector on an onnxruntime CPU session.

    ``cfg.confidence``, ``cfg.nms_iou`` and ``cfg.ignore_classes`` are read on every call (live-tunable);
    ``cfg.threads`` and ``cfg.input_size`` are read once.

    Raises :class:`DetectorError` (naming the path and the command that makes a model) if the model
    is missing, corrupt, or not a detector of :data:`CLASS_NAMES`, and (one line naming both hashes)
    if its sha256 differs from its model card's, unless ``cfg.verify_hash`` is false
    (:func:`verify_model_hash`).
    """

    def __init__(self, cfg: DetectorConfig, model_path: Path | str | None = None) -> None:
        self.cfg = cfg
        path = Path(model_path) if model_path is not None else _resolve(cfg.model_path)
        self.model_path = path
        if not path.is_file():
            raise DetectorError(f"detector model not found: {path}. Make one with: {MAKE_MODEL_COMMAND}")
        if path.stat().st_size == 0:
            raise DetectorError(f"detector model {path} is empty. Make one with: {MAKE_MODEL_COMMAND}")
        #: sha256 checked against the model card (None: not checked, or no card describes the file)
        self.sha256: str | None = verify_model_hash(path) if getattr(cfg, "verify_hash", True) else None
        #: the card's score → probability map (identity: ``calibration: off``, or the card has none);
        #: :class:`~app.ocslam.consciousness.Consciousness` applies it, the boxes keep the raw score
        self.score_calibration: ScoreCalibration = _calibration_of(path, cfg.calibration)
        import onnxruntime as ort

        opts = ort.SessionOptions()
        opts.intra_op_num_threads = int(cfg.threads)
        opts.inter_op_num_threads = 1
        opts.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
        opts.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
        opts.log_severity_level = 3
        for key, value in session_config_entries(cfg).items():
            opts.add_session_config_entry(key, value)
        try:
            self.session = ort.InferenceSession(str(path), sess_options=opts, providers=["CPUExecutionProvider"])
        except Exception as e:  # onnxruntime raises its own exception types for bad protobufs
            raise DetectorError(
                f"detector model {path} is corrupt or not an ONNX model ({type(e).__name__}: "
                f"{str(e).strip().splitlines()[0] if str(e).strip() else ''}). Make one with: {MAKE_MODEL_COMMAND}"
            ) from None
        inputs = self.session.get_inputs()
        if len(inputs) != 1 or len(inputs[0].shape) != 4:
            raise DetectorError(f"detector model {path} does not take one NCHW image. Make one with: {MAKE_MODEL_COMMAND}")
        self._input_name = inputs[0].name
        meta = self.session.get_modelmeta().custom_metadata_map
        names, trained_width = _parse_metadata(meta)
        self.class_names: tuple[str, ...] = names if names is not None else CLASS_NAMES
        if self.class_names != CLASS_NAMES:
            raise DetectorError(
                f"detector model {path} has classes {list(self.class_names)}, expected {list(CLASS_NAMES)}. "
                f"Make one with: {MAKE_MODEL_COMMAND}"
            )
        shape = inputs[0].shape
        h_in, w_in = shape[2], shape[3]
        #: fixed input (H, W) of a static model, or None for a dynamic one
        self._static: tuple[int, int] | None = (
            (int(h_in), int(w_in)) if isinstance(h_in, int) and isinstance(w_in, int) else None
        )
        if self._static is not None:
            self._width = self._static[1]
        else:
            self._width = int(cfg.input_size) if cfg.input_size > 0 else int(trained_width or 224)
            if self._width % STRIDE:
                raise DetectorError(f"detector.input_size must be a multiple of {STRIDE}, got {self._width}")
        self.trained_width = trained_width
        self.num_classes = len(self.class_names)
        self._blob: NDArray[np.float32] | None = None
        self._blob_key: tuple[int, int] | None = None
        self._lock = threading.Lock()
        # One dry run: a file that loads but computes the wrong thing fails here, not in the loop.
        probe_w, probe_h = self.input_size_for(640, 480)
        try:
            out = self.session.run(None, {self._input_name: np.zeros((1, 3, probe_h, probe_w), np.float32)})[0]
        except Exception as e:
            raise DetectorError(
                f"detector model {path} failed a test inference ({type(e).__name__}). Make one with: {MAKE_MODEL_COMMAND}"
            ) from None
        if out.ndim != 3 or out.shape[1] != 4 + self.num_classes:
            raise DetectorError(
                f"detector model {path} outputs {list(out.shape)}, expected [1, {4 + self.num_classes}, N]. "
                f"Make one with: {MAKE_MODEL_COMMAND}"
            )

    @property
    def input_size(self) -> tuple[int, int]:
        """Network input ``(width, height)`` for the camera's 4:3 images (a static model's fixed size)."""
        return self.input_size_for(640, 480)

    def input_size_for(self, width: int, height: int) -> tuple[int, int]:
        """Network input ``(width, height)`` used for an image of ``width × height``."""
        if self._static is not None:
            return self._static[1], self._static[0]
        return input_shape_for(width, height, self._width)

    def infer(self, rgb: NDArray[np.uint8]) -> tuple[NDArray[np.float32], Letterbox]:
        """Raw network output ``(1, 4 + C, N)`` for an ``(H, W, 3)`` RGB image, and its letterbox.

        The input tensor is kept between calls (its grey padding is written once per image size), so a
        stream of same-size camera images allocates nothing for preprocessing; a lock keeps concurrent
        callers from sharing it mid-frame."""
        rgb = _as_rgb(rgb)
        key = (rgb.shape[1], rgb.shape[0])
        with self._lock:
            if self._blob is None or self._blob_key != key:
                w_in, h_in = self.input_size_for(*key)
                self._blob = np.full((1, 3, h_in, w_in), np.float32(PAD_VALUE / 255.0), np.float32)
                self._blob_key = key
            blob, lb = letterbox(rgb, self._blob.shape[3], self._blob.shape[2], out=self._blob)
            out = self.session.run(None, {self._input_name: blob})[0]
        return out, lb

    def detect(self, image: Image) -> Detections:
        """Boxes in ``image``'s pixels (origin top-left, y down), best first, above ``cfg.confidence``."""
        rgb = _as_rgb(image.data)
        out, lb = self.infer(rgb)
        h, w = rgb.shape[:2]
        boxes, scores, cls = decode_output(
            out, self.num_classes, float(self.cfg.confidence), float(self.cfg.nms_iou), lb, w, h
        )
        ignore = {CLASS_INDEX[n] for n in self.cfg.ignore_classes if n in CLASS_INDEX}
        dets = tuple(
            Detection(float(b[0]), float(b[1]), float(b[2]), float(b[3]), int(c), float(s))
            for b, s, c in zip(boxes, scores, cls)
            if int(c) not in ignore
        )
        return Detections(stamp=image.stamp, image_width=w, image_height=h, boxes=dets)


def _resolve(p: str) -> Path:
    path = Path(p).expanduser()
    if path.is_absolute():
        return path
    # The project root (the core must not import app.config; this mirrors app.config.resolve_path).
    if (Path.cwd() / path).exists():
        return Path.cwd() / path
    return Path(__file__).resolve().parents[2] / path


def _as_rgb(data: NDArray) -> NDArray[np.uint8]:
    a = np.asarray(data)
    if a.dtype != np.uint8:
        raise DetectorError(f"expected a uint8 RGB image, got dtype {a.dtype}")
    if a.ndim == 2:
        a = cv2.cvtColor(a, cv2.COLOR_GRAY2RGB)
    elif a.ndim == 3 and a.shape[2] == 4:
        a = a[:, :, :3]
    if a.ndim != 3 or a.shape[2] != 3 or a.shape[0] < 8 or a.shape[1] < 8:
        raise DetectorError(f"expected an (H, W, 3) RGB image, got shape {a.shape}")
    return a


def draw_detections(rgb: NDArray[np.uint8], detections: Detections, thickness: int | None = None) -> NDArray[np.uint8]:
    """A copy of ``(H, W, 3)`` RGB ``rgb`` with each box drawn in its class colour, labelled
    ``"<class> <confidence %>"``. Boxes are rescaled if ``rgb`` is not the detections' image size."""
    out = np.ascontiguousarray(_as_rgb(rgb).copy())
    h, w = out.shape[:2]
    sx = w / detections.image_width if detections.image_width else 1.0
    sy = h / detections.image_height if detections.image_height else 1.0
    t = thickness if thickness is not None else max(1, int(round(min(w, h) / 240)))
    font_scale = max(0.35, min(w, h) / 800)
    for d in detections.boxes:
        color = CLASS_COLORS[d.class_id % len(CLASS_COLORS)]
        p1 = (int(round(d.x1 * sx)), int(round(d.y1 * sy)))
        p2 = (int(round(d.x2 * sx)), int(round(d.y2 * sy)))
        cv2.rectangle(out, p1, p2, color, t, cv2.LINE_8)
        text = f"{d.label} {int(d.confidence * 100)}%"
        (tw, th), base = cv2.getTextSize(text, cv2.FONT_HERSHEY_SIMPLEX, font_scale, 1)
        ty = p1[1] - 2 if p1[1] - th - base - 2 >= 0 else p1[1] + th + base + 2
        x0 = min(max(p1[0], 0), max(w - tw - 2, 0))
        cv2.rectangle(out, (x0, ty - th - base), (x0 + tw + 2, ty + 1), color, -1)
        luminance = 0.299 * color[0] + 0.587 * color[1] + 0.114 * color[2]
        text_color = (0, 0, 0) if luminance > 140 else (255, 255, 255)
        cv2.putText(out, text, (x0 + 1, ty - base + 1), cv2.FONT_HERSHEY_SIMPLEX, font_scale, text_color, 1, cv2.LINE_AA)
    return out
