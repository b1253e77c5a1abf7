"""A narrower YOLOv8 detector initialised from a wider trained one (structured channel pruning).

The app's latency target needs a network with fewer channels than YOLOv8n (``width_multiple`` 0.25).
Training one from scratch throws away the days of training in the wide run; instead every layer of the
narrow network takes the *most important* channels of the same layer of a trained wide network, chosen
by the magnitude of their BatchNorm scale (|γ|, "network slimming", Liu et al. 2017), and training goes
on from there (with the wide network as a distillation teacher where the trainer offers it).

Channel choices must agree wherever tensors meet:

- a layer's output channels are its consumers' input channels (``Concat`` offsets them by the widths of
  the tensors before them);
- ``C2f`` splits its first convolution's output in two halves (``chunk(2)``), so each half keeps its own
  best channels, and a ``Bottleneck`` with a shortcut (``x + f(x)``) keeps its input's channels;
- ``SPPF`` concatenates its first convolution's output with three max-pools of it (the same channels);
- the ``Detect`` head's last convolutions keep all their outputs (box distribution and class scores).

Only the modules YOLOv8 is built of are handled (``Conv``, ``C2f``/``Bottleneck``, ``SPPF``,
``nn.Upsample``, ``Concat``, ``Detect``); anything else raises :class:`ValueError` naming it.

The module needs the ``[train]`` extra (torch, ultralytics) and is imported only by the training command.
"""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["narrow_yaml", "prune_into", "prune_checkpoint", "model_width"]

#: the scale of ultralytics' yolov8 yaml the narrow variants are derived from
BASE_YAML = "yolov8n.yaml"


def model_width(model: Any) -> float:
    """The ``width_multiple`` a built ultralytics model was made with."""
    y = model.yaml
    return float(y["scales"][y.get("scale", "n")][1]) if "scales" in y else float(y.get("width_multiple", 0.25))


#: the width multiples :func:`narrow_yaml` builds (YOLOv8n is 0.25)
WIDTH_RANGE = (0.05, 0.25)
#: activations a narrow network may use instead of YOLOv8's SiLU (ultralytics' ``activation`` yaml key)
ACTIVATIONS = {"silu": None, "relu": "nn.ReLU()"}


def narrow_yaml(width: float, nc: int, out: Path, act: str = "silu") -> Path:
    """Write ultralytics' YOLOv8n description with ``width_multiple`` = ``width`` to ``out`` (a file named
    ``yolov8n-w<width>.yaml``, so ultralytics reads its scale as ``n``). ``act``: ``silu`` (YOLOv8's) or
    ``relu`` (int8 inference fuses it into the convolution; SiLU costs a quantized sigmoid and product per
    layer, a third of the int8 time of a narrow network on this CPU). Returns the file."""
    import yaml
    from ultralytics.nn.tasks import yaml_model_load

    if not WIDTH_RANGE[0] <= width <= WIDTH_RANGE[1]:
        raise ValueError(f"width must be in [{WIDTH_RANGE[0]:g}, {WIDTH_RANGE[1]:g}] (YOLOv8n is 0.25), got {width:g}")
    d = copy.deepcopy(yaml_model_load(BASE_YAML))
    for k in ("yaml_file", "scale", "channels"):
        d.pop(k, None)
    depth, _, max_ch = d["scales"]["n"]
    d["scales"] = {"n": [depth, float(width), max_ch]}
    d["nc"] = int(nc)
    if act not in ACTIVATIONS:
        raise ValueError(f"unknown activation {act!r} (known: {', '.join(ACTIVATIONS)})")
    if ACTIVATIONS[act] is not None:
        d["activation"] = ACTIVATIONS[act]
    out = Path(out)
    if not out.name.startswith("yolov8n"):
        raise ValueError(f"{out.name}: the file name must start with yolov8n (ultralytics reads the scale from it)")
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(yaml.safe_dump(d, sort_keys=False))
    return out


def _top(gamma: Any, k: int, offset: int = 0) -> np.ndarray:
    """Indices (sorted, plus ``offset``) of the ``k`` largest |γ|."""
    g = np.abs(gamma.detach().cpu().float().numpy())
    if k > g.size:
        raise ValueError(f"cannot keep {k} of {g.size} channels")
    return np.sort(np.argsort(-g, kind="stable")[:k]) + offset


def _copy_conv(src: Any, dst: Any, sel_in: np.ndarray, sel_out: np.ndarray, kept: dict[int, np.ndarray]) -> None:
    """``Conv`` (conv + BatchNorm) or a plain ``nn.Conv2d``: the kept output rows and input columns
    (recorded in ``kept`` under ``id(src)``)."""
    import torch

    si = torch.as_tensor(sel_in, dtype=torch.long)
    so = torch.as_tensor(sel_out, dtype=torch.long)
    sconv, dconv = (src.conv, dst.conv) if hasattr(src, "conv") else (src, dst)
    w = sconv.weight.detach()[so][:, si]
    if w.shape != dconv.weight.shape:
        raise ValueError(f"pruned weight {tuple(w.shape)} does not fit {tuple(dconv.weight.shape)}")
    kept[id(src)] = np.asarray(sel_out)
    with torch.no_grad():
        dconv.weight.copy_(w)
        if sconv.bias is not None:
            dconv.bias.copy_(sconv.bias.detach()[so])
        if hasattr(src, "bn"):
            for name in ("weight", "bias", "running_mean", "running_var"):
                getattr(dst.bn, name).copy_(getattr(src.bn, name).detach()[so])


def _conv(src: Any, dst: Any, sel_in: np.ndarray, kept: dict[int, np.ndarray],
          sel_out: np.ndarray | None = None) -> np.ndarray:
    """Copy a ``Conv``; its output keeps ``sel_out`` or, if None, its most important channels."""
    if sel_out is None:
        sel_out = _top(src.bn.weight, dst.conv.out_channels)
    _copy_conv(src, dst, sel_in, sel_out, kept)
    return sel_out


def _c2f(src: Any, dst: Any, sel_in: np.ndarray, kept: dict[int, np.ndarray]) -> np.ndarray:
    c, c2 = src.c, dst.c
    g = src.cv1.bn.weight
    halves = np.concatenate([_top(g[:c], c2), _top(g[c:], c2, offset=c)])
    _conv(src.cv1, dst.cv1, sel_in, kept, halves)
    parts = [halves[:c2], halves[c2:] - c]  # each half's channels, relative to the half
    for sm, dm in zip(src.m, dst.m):
        mid = _conv(sm.cv1, dm.cv1, parts[-1], kept)
        parts.append(_conv(sm.cv2, dm.cv2, mid, kept, parts[-1] if sm.add else None))
    cat = np.concatenate([p + j * c for j, p in enumerate(parts)])
    return _conv(src.cv2, dst.cv2, cat, kept)


def _sppf(src: Any, dst: Any, sel_in: np.ndarray, kept: dict[int, np.ndarray]) -> np.ndarray:
    if getattr(src, "add", False):
        raise ValueError("SPPF with a shortcut is not handled")
    c = src.cv1.conv.out_channels
    mid = _conv(src.cv1, dst.cv1, sel_in, kept)
    n = src.cv2.conv.in_channels // c  # its output and the max-pools of it: the same channels each time
    return _conv(src.cv2, dst.cv2, np.concatenate([mid + j * c for j in range(n)]), kept)


def _detect(src: Any, dst: Any, feats: list[np.ndarray], kept: dict[int, np.ndarray]) -> None:
    """Each level's box (``cv2``) and class (``cv3``) branch from that level's kept features; the DFL as it is."""
    for branches in ("cv2", "cv3"):
        for sseq, dseq, sel in zip(getattr(src, branches), getattr(dst, branches), feats):
            *inner, (sl, dl) = zip(sseq, dseq)
            for si, di in inner:
                sel = _conv(si, di, sel, kept)
            _copy_conv(sl, dl, sel, np.arange(dl.out_channels), kept)  # box distribution / class scores: all kept
    _copy_conv(src.dfl.conv, dst.dfl.conv, np.arange(src.dfl.conv.in_channels), np.arange(src.dfl.conv.out_channels),
               kept)


def prune_into(wide: Any, narrow: Any) -> dict[str, np.ndarray]:
    """Fill ultralytics DetectionModel ``narrow`` (built from :func:`narrow_yaml`) with the weights of the most
    important channels of the trained DetectionModel ``wide`` of the same layout and classes.

    Returns, for each convolution of ``wide`` (by module name), the output channels it kept."""
    from ultralytics.nn.modules import SPPF, C2f, Concat, Conv, Detect

    if len(wide.model) != len(narrow.model):
        raise ValueError(f"layouts differ: {len(wide.model)} vs {len(narrow.model)} layers")
    kept: dict[int, np.ndarray] = {}
    sels: list[np.ndarray] = []  # each layer's kept output channels (indices into the wide tensor)
    widths: list[int] = []  # each layer's wide output width
    prev_sel, prev_w = np.arange(3), 3
    for i, (s, d) in enumerate(zip(wide.model, narrow.model)):
        if type(s) is not type(d):
            raise ValueError(f"layer {i}: {type(s).__name__} vs {type(d).__name__}")
        f = s.f
        ins = [(prev_sel, prev_w) if j == -1 else (sels[j], widths[j]) for j in ([f] if isinstance(f, int) else f)]
        sel_in, w_in = ins[0]
        if isinstance(s, Conv):
            sel, w = _conv(s, d, sel_in, kept), s.conv.out_channels
        elif isinstance(s, C2f):
            sel, w = _c2f(s, d, sel_in, kept), s.cv2.conv.out_channels
        elif isinstance(s, SPPF):
            sel, w = _sppf(s, d, sel_in, kept), s.cv2.conv.out_channels
        elif type(s).__name__ == "Upsample":
            sel, w = sel_in, w_in
        elif isinstance(s, Concat):
            offs = np.cumsum([0] + [wi for _, wi in ins[:-1]])
            sel = np.concatenate([si + o for (si, _), o in zip(ins, offs)])
            w = int(sum(wi for _, wi in ins))
        elif isinstance(s, Detect):
            _detect(s, d, [si for si, _ in ins], kept)
            continue
        else:
            raise ValueError(f"layer {i}: {type(s).__name__} is not handled by the pruning")
        sels.append(sel)
        widths.append(int(w))
        prev_sel, prev_w = sel, int(w)
    narrow.names = getattr(wide, "names", narrow.names)
    return {name: kept[id(m)] for name, m in wide.named_modules() if id(m) in kept}


def prune_checkpoint(src: Path, width: float, out: Path, yaml_out: Path, act: str = "silu") -> Path:
    """Prune the EMA weights of ultralytics checkpoint ``src`` (e.g. ``assets/models/detector-train.pt``) to
    ``width`` (with activation ``act``: the weights carry over, the network adapts when trained); write the narrow
    model's yaml to ``yaml_out`` and a checkpoint ultralytics loads as ``pretrained`` to ``out``. Returns ``out``."""
    import torch
    from ultralytics.nn.tasks import DetectionModel, load_checkpoint

    wide, _ = load_checkpoint(str(src))
    wide = wide.float().eval()
    if wide.is_fused():
        raise ValueError(f"{src}: a fused model cannot be pruned (its BatchNorms are folded)")
    nc = int(wide.yaml["nc"])
    if width > model_width(wide) or (width == model_width(wide) and act == "silu"):
        raise ValueError(f"width {width} is not narrower than {src}'s {model_width(wide)}")
    narrow = DetectionModel(str(narrow_yaml(width, nc, yaml_out, act)), nc=nc, verbose=False).eval()
    prune_into(wide, narrow)
    narrow.args = getattr(wide, "args", {})
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    torch.save({"model": narrow, "ema": None, "pruned_from": str(src), "width": float(width)}, out)
    return out
