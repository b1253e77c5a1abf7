"""Inference variants of a trained detector: the app's ONNX model made from the exported float one.

:func:`optimize_for_inference` (``ocslam train-detector --optimize``): a static ``[1, 3, H, W]`` input
(:func:`static_model`, re-simplified with onnxslim), the DFL without its transpose (:func:`fast_dfl`),
then int8 QDQ quantization calibrated on renders of the training worlds (:func:`quantize_int8`) with the
detection head's outputs in float (:func:`float_head_nodes`); it writes the model and its card.
:func:`compress_weights_fp16` stores large weights as float16 behind casts (half the file).

Needs onnx and onnxslim (the ``[train]`` extra) and onnxruntime, each imported lazily inside the
functions, so importing this module costs nothing.
"""

from __future__ import annotations

import datetime as _dt
import sys
from pathlib import Path
from typing import Any

import yaml

from app.config import atomic_write_bytes, atomic_write_text, project_relative
from app.ocslam.detector import file_sha256
from app.ocslam.messages import CLASS_NAMES

__all__ = ["compress_weights_fp16", "fast_dfl", "float_head_nodes", "optimize_for_inference", "quantize_int8", "static_model"]


def compress_weights_fp16(src: Path, dst: Path, min_size: int = 1024) -> None:
    """Store the large float32 weights of an ONNX model as float16, each behind a ``Cast`` to float32.

    Halves the file; onnxruntime folds the casts when it loads the model, so inference still runs in
    float32 on the rounded weights (scores change by about 1e-4).
    """
    import numpy as np
    import onnx
    from onnx import TensorProto, helper, numpy_helper

    m = onnx.load(str(src))
    g = m.graph
    halves, casts = [], []
    for init in list(g.initializer):
        if init.data_type != TensorProto.FLOAT:
            continue
        a = numpy_helper.to_array(init)
        if a.size < min_size:
            continue
        g.initializer.remove(init)
        halves.append(numpy_helper.from_array(a.astype(np.float16), init.name + "_fp16"))
        casts.append(helper.make_node("Cast", [init.name + "_fp16"], [init.name], to=TensorProto.FLOAT, name=init.name + "_cast"))
    g.initializer.extend(halves)
    for i, c in enumerate(casts):
        g.node.insert(i, c)
    onnx.checker.check_model(m)
    onnx.save(m, str(dst))


#: Node-name prefix of ultralytics' detection head (``Detect``, layer 22 of yolov8n/yolo11n).
HEAD_PREFIX = "/model.22/"


def static_model(src: Path, dst: Path, width: int, height: int, fp16_weights: bool = False) -> dict[str, Any]:
    """Fix an exported model's input to ``[1, 3, height, width]`` and re-simplify it with onnxslim.

    Weights stored as float16 behind casts (:func:`compress_weights_fp16`) are restored to float32
    first, so every shape computation and constant folds away; ``fp16_weights`` stores them as
    float16 again afterwards. Returns a summary (nodes, output shape).
    """
    import numpy as np
    import onnx
    import onnxslim
    from onnx import TensorProto, numpy_helper

    m = onnx.load(str(src))
    g = m.graph
    inits = {i.name: i for i in g.initializer}
    for c in [n for n in g.node if n.op_type == "Cast" and n.input[0] in inits]:
        if inits[c.input[0]].data_type != TensorProto.FLOAT16:
            continue
        a = numpy_helper.to_array(inits[c.input[0]]).astype(np.float32)
        g.initializer.remove(inits[c.input[0]])
        g.initializer.append(numpy_helper.from_array(a, c.output[0]))
        g.node.remove(c)
    if len(g.input) != 1 or len(g.input[0].type.tensor_type.shape.dim) != 4:
        raise ValueError(f"{src}: expected one NCHW input")
    for d, v in zip(g.input[0].type.tensor_type.shape.dim, (1, 3, int(height), int(width))):
        d.Clear()
        d.dim_value = v
    for o in g.output:
        o.type.tensor_type.shape.Clear()  # re-inferred for the static input
    m = onnxslim.slim(m)
    dfl = fast_dfl(m)
    onnx.checker.check_model(m, full_check=True)
    onnx.save(m, str(dst))
    if fp16_weights:
        compress_weights_fp16(Path(dst), Path(dst))
    out = onnx.load(str(dst)).graph.output[0]
    return {"nodes": len(m.graph.node), "output": [d.dim_value for d in out.type.tensor_type.shape.dim], "fast_dfl": dfl}


def fast_dfl(model: Any) -> bool:
    """Rewrite the head's distribution focal loss decoding (``Reshape [1, 4, 16, N] → Transpose →
    Softmax(axis 1) → 1×1 Conv with weights 0…15``) as a softmax expectation along axis 2 without the
    transpose: ``Σ k·exp(x_k − max) / Σ exp(x_k − max)`` (ReduceMax, Sub, Exp, Mul, ReduceSum, Div).
    onnxruntime's Softmax on a non-last axis transposes internally and took ~10 % of the int8 model's
    time. Same result to float rounding. Changes ``model`` in place; False if the pattern is absent."""
    import numpy as np
    from onnx import helper, numpy_helper

    g = model.graph
    prod = {o: n for n in g.node for o in n.output}
    cons: dict[str, list] = {}
    for n in g.node:
        for i in n.input:
            cons.setdefault(i, []).append(n)
    inits = {i.name: i for i in g.initializer}
    for sm in [n for n in g.node if n.op_type == "Softmax"]:
        tr = prod.get(sm.input[0])
        users = cons.get(sm.output[0], [])
        if tr is None or tr.op_type != "Transpose" or len(users) != 1 or users[0].op_type != "Conv":
            continue
        perm = next((list(a.ints) for a in tr.attribute if a.name == "perm"), None)
        conv = users[0]
        if perm != [0, 2, 1, 3] or len(conv.input) != 2 or conv.input[1] not in inits:
            continue
        w = numpy_helper.to_array(inits[conv.input[1]]).astype(np.float32).reshape(-1)
        x, p = tr.input[0], sm.name + "_fast"
        k = numpy_helper.from_array(w.reshape(1, 1, -1, 1), p + "/k")
        axes = numpy_helper.from_array(np.array([2], np.int64), p + "/axes")
        g.initializer.extend([k, axes])
        new = [
            helper.make_node("ReduceMax", [x, axes.name], [p + "/max"], name=p + "/ReduceMax", keepdims=1),
            helper.make_node("Sub", [x, p + "/max"], [p + "/centred"], name=p + "/Sub"),
            helper.make_node("Exp", [p + "/centred"], [p + "/exp"], name=p + "/Exp"),
            helper.make_node("ReduceSum", [p + "/exp", axes.name], [p + "/den"], name=p + "/ReduceSumDen", keepdims=1),
            helper.make_node("Mul", [p + "/exp", k.name], [p + "/weighted"], name=p + "/Mul"),
            helper.make_node("ReduceSum", [p + "/weighted", axes.name], [p + "/num"], name=p + "/ReduceSumNum", keepdims=1),
            helper.make_node("Div", [p + "/num", p + "/den"], [conv.output[0]], name=p + "/Div"),
        ]
        pos = list(g.node).index(tr)
        for n in (tr, sm, conv):
            g.node.remove(n)
        for i, n in enumerate(new):
            g.node.insert(pos + i, n)
        g.initializer.remove(inits[conv.input[1]])
        for vi in [v for v in g.value_info if v.name == conv.output[0]]:
            g.value_info.remove(vi)  # was [1, 1, 4, N]; now [1, 4, 1, N] (the Reshape after it is unchanged)
        return True
    return False


def float_head_nodes(model: Any, head_prefix: str = HEAD_PREFIX, quantize_hidden_convs: bool = True) -> list[str]:
    """Names of the nodes kept in float by :func:`quantize_int8`: the detection head's box and class
    outputs and everything after them (DFL softmax, box decoding, the final concatenations). With
    ``quantize_hidden_convs`` the head's inner 3×3 convolutions (``cv2.k.0/1``, ``cv3.k.0/1``) are
    quantized; only each branch's last convolution stays float."""
    import re

    hidden = re.compile(re.escape(head_prefix) + r"cv[23]\.\d+/cv[23]\.\d+\.[01]/")
    names = []
    for n in model.graph.node:
        if not n.name.startswith(head_prefix):
            continue
        if quantize_hidden_convs and hidden.match(n.name):
            continue
        names.append(n.name)
    return names


class _CalibrationReader:
    """onnxruntime ``CalibrationDataReader`` over RGB images, letterboxed as :class:`Detector` does."""

    def __init__(self, images: list, input_name: str, width: int, height: int) -> None:
        from app.ocslam.detector import letterbox

        self._blobs = iter([{input_name: letterbox(im, width, height)[0]} for im in images])

    def get_next(self):
        return next(self._blobs, None)

    def rewind(self) -> None:  # pragma: no cover - onnxruntime calls it only for some methods
        pass


def load_rgb_images(folder: Path, limit: int | None = None, seed: int = 0) -> list:
    """RGB uint8 images of a dataset folder (``images/**/*.png`` or a folder of PNGs), a seeded sample
    of at most ``limit``."""
    import cv2
    import numpy as np

    folder = Path(folder)
    files = sorted(folder.glob("images/*/*.png")) or sorted(folder.glob("*.png"))
    if not files:
        raise FileNotFoundError(f"no PNG images under {folder} (expected an `ocslam dataset` folder)")
    if limit is not None and len(files) > limit:
        idx = np.random.default_rng(seed).choice(len(files), size=limit, replace=False)
        files = [files[i] for i in sorted(idx)]
    out = []
    for f in files:
        bgr = cv2.imread(str(f), cv2.IMREAD_COLOR)
        if bgr is not None:
            out.append(np.ascontiguousarray(bgr[:, :, ::-1]))
    return out


def quantize_int8(
    src: Path,
    dst: Path,
    calib_images: list,
    quantize_hidden_convs: bool = True,
    per_channel: bool = True,
    method: str = "minmax",
    op_types: tuple[str, ...] | None = None,
    float_prefixes: tuple[str, ...] = (),
) -> dict[str, Any]:
    """onnxruntime static int8 quantization (QDQ, signed int8 activations and weights) of a
    static-shape float model, calibrated on ``calib_images`` (RGB renders), with the detection head's
    outputs and the final concatenations kept in float (:func:`float_head_nodes`). Returns the recipe
    (for the model card)."""
    import onnx
    from onnxruntime.quantization import CalibrationMethod, QuantFormat, QuantType, quantize_static

    m = onnx.load(str(src))
    inp = m.graph.input[0]
    dims = [d.dim_value for d in inp.type.tensor_type.shape.dim]
    if len(dims) != 4 or min(dims) <= 0:
        raise ValueError(f"{src}: quantization needs a static input shape, got {dims}")
    height, width = dims[2], dims[3]
    exclude = float_head_nodes(m, quantize_hidden_convs=quantize_hidden_convs)
    exclude += [n.name for n in m.graph.node if any(n.name.startswith(p) for p in float_prefixes) and n.name not in exclude]
    methods = {"minmax": CalibrationMethod.MinMax, "percentile": CalibrationMethod.Percentile,
               "entropy": CalibrationMethod.Entropy}
    extra: dict[str, Any] = {"ActivationSymmetric": False, "WeightSymmetric": True}
    if method == "percentile":
        extra["CalibPercentile"] = 99.999
    quantize_static(
        str(src),
        str(dst),
        _CalibrationReader(calib_images, inp.name, width, height),
        quant_format=QuantFormat.QDQ,
        op_types_to_quantize=list(op_types) if op_types else None,
        per_channel=per_channel,
        activation_type=QuantType.QUInt8,
        weight_type=QuantType.QInt8,
        nodes_to_exclude=exclude,
        calibrate_method=methods[method],
        extra_options=extra,
    )
    import onnxruntime

    return {
        "tool": f"onnxruntime {onnxruntime.__version__} quantize_static",
        "format": "QDQ",
        "activations": "uint8 (asymmetric, per tensor; u8s8 is the x86 VNNI path)",
        "weights": "int8 (symmetric, " + ("per channel)" if per_channel else "per tensor)"),
        "calibration": f"{method}, {len(calib_images)} images",
        "op_types": list(op_types) if op_types else "onnxruntime's default",
        "float_nodes": (
            "the detection head's last convolution of each branch and everything after it (DFL, box decoding, "
            "sigmoid, final concatenations)" if quantize_hidden_convs else "the whole detection head (layer 22)"
        ),
        "float_prefixes": list(float_prefixes),
        "float_node_count": len(exclude),
    }


def optimize_for_inference(
    src: Path,
    out: Path,
    calib: Path,
    width: int = 224,
    height: int = 192,
    calib_images: int = 120,
    seed: int = 0,
    float_prefixes: tuple[str, ...] = ("/model.0/",),
    card_path: Path | None = None,
    log=print,
) -> dict[str, Any]:
    """Make the app's inference model from a trained float one: static ``[1, 3, height, width]`` input,
    simplified, the DFL without its transpose (:func:`fast_dfl`), then int8 QDQ quantization calibrated
    on ``calib_images`` renders of the ``ocslam dataset`` at ``calib`` (training worlds, never the
    held-out ones) with the detection head's outputs in float. Writes ``out`` and its card (``card_path``,
    default ``out`` with ``.yaml``), which also describes ``src`` as the float reference (``variants``,
    ``lineage.previous``) and keeps the source card's dataset, training and validation sections.
    Returns the card."""
    import tempfile

    from app.ocslam.detector import find_model_card

    src, out, calib = Path(src), Path(out), Path(calib)
    src_card: dict[str, Any] = {}
    found = find_model_card(src)
    if found is not None:
        src_card = yaml.safe_load(found[0].read_text()) or {}
    calib_meta: dict[str, Any] = {}
    if (calib / "data.yaml").is_file():
        calib_meta = (yaml.safe_load((calib / "data.yaml").read_text()) or {}).get("ocslam", {}) or {}
    images = load_rgb_images(calib, limit=calib_images, seed=seed)
    with tempfile.TemporaryDirectory(prefix="ocslam-optimize-") as tmp:
        static = Path(tmp) / "static.onnx"
        log(f"static {width}×{height} float model from {src}")
        summary = static_model(src, static, width, height)
        q = Path(tmp) / "int8.onnx"
        log(f"int8 QDQ quantization, calibrated on {len(images)} images of {calib}")
        recipe = quantize_int8(static, q, images, float_prefixes=float_prefixes)
        atomic_write_bytes(out, q.read_bytes())
    recipe["calibration_data"] = {
        "path": project_relative(calib),
        "command": calib_meta.get("command"),
        "seed": calib_meta.get("seed"),
        "images_used": len(images),
        "sample_seed": seed,
    }
    recipe["command"] = (
        " ".join(["ocslam", "train-detector", *sys.argv[2:]]) if sys.argv[1:2] == ["train-detector"] else None
    )
    src_entry = dict(src_card.get("model") or {})
    card: dict[str, Any] = {
        "model": {
            "file": out.name,
            "architecture": src_entry.get("architecture", "yolov8n"),
            "format": f"onnx, static input [1, 3, {height}, {width}], int8 QDQ (uint8 activations, int8 weights) with "
            "the detection head's outputs in float; output [1, 4 + classes, N] (cx, cy, w, h, class scores)",
            "size_bytes": out.stat().st_size,
            "sha256": file_sha256(out),
            "pretrained": False,
        },
        "classes": list(CLASS_NAMES),
        "input": {
            "width": width,
            "height": height,
            "static": True,
            "camera_640x480": [width, height],
            "note": "the app's 320×240 render (and the camera's 640×480) is scaled to 224×168 and letterboxed to 224×192",
        },
        "quantization": recipe,
        "graph": {
            "static_shape": f"[1, 3, {height}, {width}], simplified with onnxslim ({summary['nodes']} nodes)",
            "dfl": "softmax expectation along the bin axis, no transpose (same outputs to float rounding)"
            if summary.get("fast_dfl") else "as exported",
        },
        "lineage": {
            "previous": {"file": src.name, "sha256": file_sha256(src), "size_bytes": src.stat().st_size,
                         "format": src_entry.get("format")},
            "steps": [
                f"{src.name}: trained as described under training (float, dynamic input)",
                f"{out.name}: {src.name} with a static {width}×{height} input, fast DFL, int8 static quantization",
            ],
        },
        "variants": [
            {"file": src.name, "sha256": file_sha256(src), "role": "float reference (the trained weights, dynamic input, "
             "weights stored as float16, computed in float32); the model the int8 one was quantized from"}
        ],
        "dataset": src_card.get("dataset"),
        "training": src_card.get("training"),
        "validation": src_card.get("validation"),
        "date": _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"),
    }
    card_path = Path(card_path) if card_path else out.with_suffix(".yaml")
    atomic_write_text(card_path, "# Model card of the OCSLAM detector (written by `ocslam train-detector`)\n"
                      + yaml.safe_dump(card, sort_keys=False, width=110, allow_unicode=True))
    log(f"wrote {out} ({out.stat().st_size / 1e6:.1f} MB) and {card_path}")
    return card
