"""Recover a trainable ultralytics checkpoint from an exported float ONNX detector (``--init-onnx``).

The committed ``detector-v3.onnx`` holds every trained weight, but its PyTorch checkpoint was not kept, so
further training would otherwise restart from scratch. :func:`onnx_to_checkpoint` builds the same
ultralytics ``DetectionModel`` that :mod:`app.training.train` trains (``yolov8n.yaml``, scale from the
name, the app's 11 classes) and loads the ONNX initializers into it:

- every ultralytics ``Conv`` (conv + BatchNorm + SiLU; the export fused the BN into the convolution)
  takes the fused weight, and its BatchNorm becomes an affine identity plus the fused bias: weight 1,
  bias = fused bias, running mean 0, running variance ``1 − eps``, so in eval mode
  ``(x − 0) / sqrt(1 − eps + eps) · 1 + b = x + b``;
- with calibration images (:func:`calibrate_batchnorm`, ``calib_images=``) the BatchNorm instead gets
  the per-channel mean ``m`` and variance ``v`` of the fused convolution's output on real images:
  running mean ``m``, running variance ``v``, weight ``sqrt(v + eps)``, bias ``b + m``. Eval mode is
  the same function (``(x − m) / sqrt(v + eps) · sqrt(v + eps) + b + m = x + b``), and training mode —
  which normalises by the *batch's* statistics — then computes nearly the same thing too, instead of
  re-normalising every layer to unit variance as the identity BN would on the first training step;
- the plain ``nn.Conv2d`` layers (the Detect head's last convolution of each branch) take weight and
  bias directly; the DFL convolution keeps its fixed ``0…15`` weights (checked against the ONNX).

ONNX ``Conv`` nodes are matched to the torch convolutions by their weight's name (ultralytics exports
``model.3.conv.weight``; float16-stored weights are followed back through their ``Cast``), falling back
to graph order for unnamed weights, and every match is checked (weight shape, groups, stride, padding,
dilation, bias present): the first mismatch raises :class:`OnnxInitError` in one line naming both sides.

The result is saved like ultralytics' stripped ``best.pt`` (a dict whose ``model`` is the float32
``DetectionModel``), which ultralytics accepts as ``pretrained=`` (``--init-weights``).

Needs the ``[train]`` extra (torch, ultralytics, onnx), imported lazily inside the functions.
"""

from __future__ import annotations

import datetime as _dt
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from app.ocslam.messages import CLASS_NAMES

__all__ = ["OnnxConv", "OnnxInitError", "OnnxInitResult", "build_detection_model", "calibrate_batchnorm",
           "load_onnx_weights", "onnx_to_checkpoint", "read_onnx_convs"]


class OnnxInitError(ValueError):
    """The ONNX model's convolutions do not fit the ultralytics model built from the yaml."""


@dataclass
class OnnxConv:
    """One ONNX ``Conv`` node: its name, weight name and arrays (float32) and attributes."""

    node: str
    weight_name: str
    weight: Any  # numpy float32 (out, in/groups, kh, kw)
    bias: Any | None  # numpy float32 (out,) or None
    group: int = 1
    strides: tuple[int, ...] = (1, 1)
    pads: tuple[int, ...] = (0, 0, 0, 0)
    dilations: tuple[int, ...] = (1, 1)


@dataclass
class OnnxInitResult:
    """What :func:`onnx_to_checkpoint` wrote and how the convolutions were matched."""

    checkpoint: Path
    convs_loaded: int  # conv + BN pairs and plain convs that took ONNX weights
    matched_by_name: int
    matched_by_order: int
    bn_calibrated: bool
    model: Any = field(repr=False, default=None)  # the DetectionModel (eval mode), for checks


def _shape(a: Any) -> str:
    return "×".join(str(int(s)) for s in a.shape)


def read_onnx_convs(onnx_path: Path) -> list[OnnxConv]:
    """The ``Conv`` nodes of an ONNX model in graph order, with their weights as float32 arrays.

    A weight or bias may be an initializer, a ``Constant`` node, or either behind ``Cast`` /
    ``Identity`` nodes (float16 storage, :func:`app.training.optimize.compress_weights_fp16`)."""
    import numpy as np
    import onnx
    from onnx import numpy_helper

    m = onnx.load(str(onnx_path))
    g = m.graph
    consts: dict[str, Any] = {i.name: numpy_helper.to_array(i) for i in g.initializer}
    producers: dict[str, Any] = {}
    for n in g.node:
        for o in n.output:
            producers[o] = n
        if n.op_type == "Constant":
            for a in n.attribute:
                if a.name == "value":
                    consts[n.output[0]] = numpy_helper.to_array(a.t)

    def resolve(name: str) -> tuple[str, Any] | None:
        """(the source tensor's name, its value as float32) for a constant input, else None."""
        seen = 0
        while name not in consts:
            p = producers.get(name)
            if p is None or p.op_type not in ("Cast", "Identity") or seen > 8:
                return None
            name, seen = p.input[0], seen + 1
        return name, np.asarray(consts[name], dtype=np.float32)

    out: list[OnnxConv] = []
    for n in g.node:
        if n.op_type != "Conv":
            continue
        w = resolve(n.input[1]) if len(n.input) > 1 else None
        if w is None:
            raise OnnxInitError(f"{onnx_path}: Conv node {n.name!r} has no constant weight (not an exported float model?)")
        b = resolve(n.input[2]) if len(n.input) > 2 and n.input[2] else None
        attrs = {a.name: onnx.helper.get_attribute_value(a) for a in n.attribute}
        # the name the exporter gave the weight (model.3.conv.weight); a float16 copy is named <that>_fp16
        wname = n.input[1] if n.input[1].endswith(".weight") else w[0].removesuffix("_fp16")
        out.append(OnnxConv(
            node=n.name or f"Conv#{len(out)}", weight_name=wname, weight=w[1], bias=None if b is None else b[1],
            group=int(attrs.get("group", 1)), strides=tuple(int(s) for s in attrs.get("strides", (1, 1))),
            pads=tuple(int(p) for p in attrs.get("pads", (0, 0, 0, 0))),
            dilations=tuple(int(d) for d in attrs.get("dilations", (1, 1))),
        ))
    return out


def build_detection_model(model_yaml: str = "yolov8n.yaml", names: Sequence[str] = CLASS_NAMES) -> Any:
    """The ultralytics ``DetectionModel`` that ``ocslam train-detector`` trains: built from its yaml
    (the scale from the name, ``yolov8n`` → n; never a ``.pt`` download), ``nc = len(names)``, the
    app's class names, ultralytics' BatchNorm settings (eps 1e-3, momentum 0.03)."""
    from app.training.train import _import_yolo

    _import_yolo()  # TrainingUnavailable with the install hint when the [train] extra is missing
    from ultralytics.nn.tasks import DetectionModel

    model = DetectionModel(str(model_yaml), ch=3, nc=len(names), verbose=False)
    model.names = dict(enumerate(names))
    return model


def _torch_convs(model: Any) -> list[tuple[str, Any, str, Any]]:
    """(name, nn.Conv2d, kind, BatchNorm2d or None) for every convolution, in module order; kind is
    ``fused`` (ultralytics ``Conv``: conv + bn), ``plain`` (own bias) or ``dfl`` (fixed weights)."""
    import torch.nn as nn
    from ultralytics.nn.modules.block import DFL

    parents = dict(model.named_modules())
    out = []
    for name, mod in model.named_modules():
        if not isinstance(mod, nn.Conv2d):
            continue
        parent = parents.get(name.rsplit(".", 1)[0]) if "." in name else None
        bn = getattr(parent, "bn", None) if parent is not None and getattr(parent, "conv", None) is mod else None
        if isinstance(parent, DFL):
            out.append((name, mod, "dfl", None))
        elif isinstance(bn, nn.BatchNorm2d):
            out.append((name, mod, "fused", bn))
        else:
            out.append((name, mod, "plain", None))
    return out


def _check_fit(src: str, oc: OnnxConv, name: str, conv: Any, kind: str) -> None:
    """One-line OnnxInitError when the ONNX node cannot be the torch convolution."""
    def pair(v: Any) -> tuple[int, int]:
        return (int(v), int(v)) if isinstance(v, int) else (int(v[0]), int(v[1]))

    want_w = tuple(conv.weight.shape)
    pads = pair(conv.padding) if not isinstance(conv.padding, str) else None
    problems = []
    if tuple(oc.weight.shape) != want_w:
        problems.append(f"weight {_shape(oc.weight)} vs {'×'.join(map(str, want_w))}")
    if oc.group != conv.groups:
        problems.append(f"groups {oc.group} vs {conv.groups}")
    if tuple(oc.strides) != pair(conv.stride):
        problems.append(f"stride {oc.strides} vs {pair(conv.stride)}")
    if tuple(oc.dilations) != pair(conv.dilation):
        problems.append(f"dilation {oc.dilations} vs {pair(conv.dilation)}")
    if pads is not None and tuple(oc.pads) != (pads[0], pads[1], pads[0], pads[1]):
        problems.append(f"pads {oc.pads} vs {pads}")
    if kind in ("fused", "plain") and oc.bias is None:
        problems.append("no bias in the ONNX")
    if oc.bias is not None and tuple(oc.bias.shape) != (want_w[0],):
        problems.append(f"bias {_shape(oc.bias)} vs {want_w[0]}")
    if problems:
        raise OnnxInitError(f"{src}: ONNX Conv {oc.node!r} ({oc.weight_name}) does not fit {name} ({kind}): {'; '.join(problems)}")


def load_onnx_weights(model: Any, onnx_path: Path) -> tuple[int, int, int]:
    """Load the ONNX model's convolutions into ``model`` (see the module docstring). Returns (convs
    loaded, matched by weight name, matched by graph order). Raises :class:`OnnxInitError` naming the
    first ONNX node that does not fit, or the first torch convolution left without weights."""
    import numpy as np
    import torch

    src = Path(onnx_path).name
    onnx_convs = read_onnx_convs(Path(onnx_path))
    convs = _torch_convs(model)
    by_name = {name: (name, conv, kind, bn) for name, conv, kind, bn in convs}
    unassigned = [c[0] for c in convs]
    pairs: list[tuple[OnnxConv, tuple[str, Any, str, Any]]] = []
    n_name = n_order = 0
    for oc in onnx_convs:
        key = oc.weight_name.removesuffix(".weight")
        if key in by_name and key in unassigned:
            target, n_name = by_name[key], n_name + 1
        else:  # no usable name: the next convolution in module order (checked below like any match)
            if not unassigned:
                raise OnnxInitError(f"{src}: ONNX Conv {oc.node!r} ({oc.weight_name}) has no convolution left in the model "
                                    f"({len(onnx_convs)} ONNX convs, {len(convs)} in the model)")
            target, n_order = by_name[unassigned[0]], n_order + 1
        _check_fit(src, oc, target[0], target[1], target[2])
        unassigned.remove(target[0])
        pairs.append((oc, target))
    if unassigned:
        raise OnnxInitError(f"{src}: {unassigned[0]} (and {len(unassigned) - 1} more) of the model got no ONNX weights "
                            f"({len(onnx_convs)} ONNX convs, {len(convs)} in the model)")

    loaded = 0
    with torch.no_grad():
        for oc, (name, conv, kind, bn) in pairs:
            w = torch.from_numpy(np.array(oc.weight, dtype=np.float32))
            if kind == "dfl":
                if not torch.equal(w, conv.weight.detach().cpu()):
                    raise OnnxInitError(f"{src}: ONNX Conv {oc.node!r} is the DFL but its weights are not 0…{w.shape[1] - 1}")
                continue
            conv.weight.copy_(w)
            b = torch.from_numpy(np.array(oc.bias, dtype=np.float32))
            if kind == "plain":
                conv.bias.copy_(b)
            else:
                if conv.bias is not None:
                    raise OnnxInitError(f"{src}: {name} has its own bias besides its BatchNorm")
                bn.weight.fill_(1.0)
                bn.bias.copy_(b)
                bn.running_mean.zero_()
                bn.running_var.fill_(1.0 - bn.eps)
            loaded += 1
    return loaded, n_name, n_order


def _letterbox_batch(paths: Sequence[Path], imgsz: int) -> Any:
    """Images as ultralytics feeds them: RGB, long side ``imgsz``, centred on grey 114 in an
    ``imgsz``×``imgsz`` square, float in [0, 1], NCHW."""
    import cv2
    import numpy as np
    import torch

    out = np.full((len(paths), imgsz, imgsz, 3), 114, dtype=np.uint8)
    for i, p in enumerate(paths):
        im = cv2.imread(str(p), cv2.IMREAD_COLOR)
        if im is None:
            raise FileNotFoundError(f"cannot read calibration image {p}")
        h, w = im.shape[:2]
        s = imgsz / max(h, w)
        nh, nw = max(1, round(h * s)), max(1, round(w * s))
        im = cv2.resize(im, (nw, nh), interpolation=cv2.INTER_AREA if s < 1 else cv2.INTER_LINEAR)
        y0, x0 = (imgsz - nh) // 2, (imgsz - nw) // 2
        out[i, y0:y0 + nh, x0:x0 + nw] = im[:, :, ::-1]
    return torch.from_numpy(out).permute(0, 3, 1, 2).float().div_(255.0)


def calibrate_batchnorm(model: Any, images: Sequence[Path], imgsz: int = 224, batch: int = 16) -> int:
    """Give every ultralytics ``Conv``'s BatchNorm (loaded as an identity plus bias) the statistics of
    its convolution's output on ``images``, keeping the eval-mode function unchanged (module
    docstring). Returns the number of BatchNorms set. The model must hold identity BNs
    (:func:`load_onnx_weights`); it is left in eval mode."""
    import torch

    fused = [(name, conv, bn) for name, conv, kind, bn in _torch_convs(model) if kind == "fused"]
    sums: dict[str, list[Any]] = {name: [0.0, None, None] for name, _, _ in fused}  # count, sum, sum of squares

    def hook(name: str):
        def f(_mod: Any, _inp: Any, out: Any) -> None:
            x = out.detach().double()
            s = sums[name]
            s[0] += x.shape[0] * x.shape[2] * x.shape[3]
            s1, s2 = x.sum(dim=(0, 2, 3)), (x * x).sum(dim=(0, 2, 3))
            s[1] = s1 if s[1] is None else s[1] + s1
            s[2] = s2 if s[2] is None else s[2] + s2
        return f

    handles = [conv.register_forward_hook(hook(name)) for name, conv, _ in fused]
    model.eval()
    try:
        with torch.no_grad():
            for i in range(0, len(images), batch):
                model(_letterbox_batch(images[i:i + batch], imgsz))
    finally:
        for h in handles:
            h.remove()
    with torch.no_grad():
        for name, _conv, bn in fused:
            n, s1, s2 = sums[name]
            if not n:
                raise OnnxInitError(f"BatchNorm calibration: {name} saw no data")
            mean = s1 / n
            var = (s2 / n - mean * mean).clamp_min(0.0)
            # a dead channel (constant output) keeps a unit scale instead of a zero one
            var = torch.where(var > 1e-6, var, torch.ones_like(var))
            bias = bn.bias.detach().double()
            bn.running_mean.copy_(mean.float())
            bn.running_var.copy_(var.float())
            bn.weight.copy_(torch.sqrt(var + bn.eps).float())
            bn.bias.copy_((bias + mean).float())
    return len(fused)


def onnx_to_checkpoint(
    onnx_path: Path,
    out_pt: Path,
    model_yaml: str = "yolov8n.yaml",
    names: Sequence[str] = CLASS_NAMES,
    imgsz: int = 224,
    calib_images: Sequence[Path] | None = None,
) -> OnnxInitResult:
    """Convert a float ONNX detector exported by ultralytics (``ocslam train-detector``) into a
    checkpoint ultralytics accepts as ``pretrained=`` (``--init-weights``), with the same outputs.

    ``calib_images`` (training images): BatchNorm statistics from them instead of identity BNs (module
    docstring); the eval-mode outputs are the same either way. Raises :class:`OnnxInitError` (a
    ValueError) when the ONNX model is not this architecture, FileNotFoundError when it is missing."""
    import torch

    onnx_path, out_pt = Path(onnx_path), Path(out_pt)
    if not onnx_path.is_file():
        raise FileNotFoundError(f"no ONNX model at {onnx_path}")
    from app.config import PROJECT_ROOT
    from app.training.train import setup_offline

    setup_offline(PROJECT_ROOT / ".yolo")
    model = build_detection_model(model_yaml, names)
    loaded, n_name, n_order = load_onnx_weights(model, onnx_path)
    calibrated = False
    if calib_images:
        calibrate_batchnorm(model, list(calib_images), imgsz=imgsz)
        calibrated = True
    model.float().eval()
    import ultralytics

    ckpt = {
        "date": _dt.datetime.now(_dt.timezone.utc).isoformat(),
        "version": str(ultralytics.__version__),
        "epoch": -1,
        "best_fitness": None,
        "model": model,
        "ema": None,
        "updates": None,
        "optimizer": None,
        "train_args": {"model": str(model_yaml), "task": "detect", "imgsz": int(imgsz)},
        "ocslam": {
            "source_onnx": str(onnx_path),
            "batchnorm": f"calibrated on {len(calib_images or ())} images" if calibrated else "identity + fused bias",
        },
    }
    out_pt.parent.mkdir(parents=True, exist_ok=True)
    tmp = out_pt.with_name(out_pt.name + ".tmp")
    torch.save(ckpt, str(tmp))
    tmp.replace(out_pt)
    return OnnxInitResult(out_pt, loaded, n_name, n_order, calibrated, model)
