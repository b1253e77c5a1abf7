"""Structured pruning of YOLOv8n into a narrower network (app.training.narrow) and `train-detector --width`.

Known answers: pruning to the same width is the identity; a wide network whose dropped channels are dead
(BatchNorm scale and shift zero, so they output exactly 0) computes exactly what its pruned copy computes.
Runs only where the [train] extra is installed (not in `make test`'s default venv).
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytestmark = [pytest.mark.train]
torch = pytest.importorskip("torch")
pytest.importorskip("ultralytics")

ROOT = Path(__file__).resolve().parents[1]


def _random_model(width: float, tmp: Path, seed: int):
    from ultralytics.nn.tasks import DetectionModel

    from app.training.narrow import narrow_yaml

    torch.manual_seed(seed)
    m = DetectionModel(str(narrow_yaml(width, 11, tmp / f"yolov8n-w{width:g}.yaml")), nc=11, verbose=False).eval()
    g = torch.Generator().manual_seed(seed)
    with torch.no_grad():  # BatchNorms that are not the identity, with scales of very different sizes
        for mod in m.modules():
            if isinstance(mod, torch.nn.BatchNorm2d):
                n = mod.num_features
                mod.weight.copy_(torch.rand(n, generator=g) * 2 - 1)
                mod.bias.copy_(torch.randn(n, generator=g) * 0.1)
                mod.running_mean.copy_(torch.randn(n, generator=g) * 0.1)
                mod.running_var.copy_(torch.rand(n, generator=g) + 0.5)
    return m


def test_same_width_is_identity(tmp_path: Path) -> None:
    from app.training.narrow import prune_into

    wide = _random_model(0.25, tmp_path, 0)
    same = _random_model(0.25, tmp_path, 1)
    prune_into(wide, same)
    x = torch.rand(2, 3, 96, 128)
    assert torch.equal(wide(x)[0], same(x)[0])


@pytest.mark.parametrize("width", [0.1875, 0.125])
def test_dead_channels_are_the_dropped_ones(tmp_path: Path, width: float) -> None:
    from ultralytics.nn.modules import Conv

    from app.training.narrow import prune_into

    wide = _random_model(0.25, tmp_path, 2)
    narrow = _random_model(width, tmp_path, 3)
    kept = prune_into(wide, narrow)
    mods = dict(wide.named_modules())
    convs = [n for n, m in mods.items() if isinstance(m, Conv)]
    assert set(convs) <= set(kept)
    fewer = 0
    with torch.no_grad():  # kill every channel the pruning dropped: it then outputs exactly SiLU(0) = 0
        for name in convs:
            bn = mods[name].bn
            drop = np.setdiff1d(np.arange(bn.num_features), kept[name])
            fewer += drop.size > 0
            bn.weight[drop] = 0.0
            bn.bias[drop] = 0.0
    assert fewer > 40  # most layers really are narrower
    x = torch.rand(2, 3, 96, 128)
    a, b = wide(x)[0], narrow(x)[0]
    assert a.shape == b.shape
    assert torch.allclose(a, b, atol=1e-4, rtol=1e-4)


def test_keeps_the_largest_batchnorm_scales(tmp_path: Path) -> None:
    from app.training.narrow import prune_into

    wide = _random_model(0.25, tmp_path, 4)
    narrow = _random_model(0.125, tmp_path, 5)
    kept = prune_into(wide, narrow)
    first = wide.model[0]  # a plain Conv: free to keep its 8 largest |γ| of 16
    g = first.bn.weight.detach().abs().numpy()
    assert sorted(kept["model.0"]) == sorted(np.argsort(-g)[:8])
    assert narrow.model[0].conv.weight.shape[0] == 8


def test_prune_checkpoint_refuses_wider_and_loads(tmp_path: Path) -> None:
    from ultralytics.nn.tasks import load_checkpoint

    from app.training.narrow import prune_checkpoint

    wide = _random_model(0.25, tmp_path, 6)
    src = tmp_path / "wide.pt"
    torch.save({"model": wide, "ema": None}, src)
    with pytest.raises(ValueError, match="not narrower"):
        prune_checkpoint(src, 0.25, tmp_path / "p.pt", tmp_path / "yolov8n-x.yaml")
    out = prune_checkpoint(src, 0.125, tmp_path / "p.pt", tmp_path / "yolov8n-w0.125.yaml")
    m, _ = load_checkpoint(str(out))
    assert m.model[0].conv.out_channels == 8
    assert m(torch.rand(1, 3, 64, 64))[0].shape[1] == 4 + 11


@pytest.mark.parametrize(
    "args, message",
    [
        (["--resume", "--width", "0.125"], "start a new run"),
        (["--init-prune", "x.pt"], "need --width"),
        (["--act", "relu"], "need --width"),
        (["--width", "0.3"], "must be in"),
        (["--width", "0.125", "--init-prune", "no/such.pt"], "no checkpoint at"),
        (["--width", "0.125", "--distill", "no/such.pt"], "no checkpoint at"),
    ],
)
def test_cli_refuses_misuse(args: list[str], message: str) -> None:
    r = subprocess.run([sys.executable, "-m", "app", "train-detector", *args], cwd=ROOT, capture_output=True,
                       text=True, timeout=120)
    assert r.returncode == 2
    assert message in r.stderr and len(r.stderr.strip().splitlines()) == 1


def test_relu_variant(tmp_path: Path) -> None:
    """--act relu: the same layout with ReLU (fused into int8 convolutions); the pruned weights carry over."""
    from ultralytics.nn.tasks import load_checkpoint

    from app.training.narrow import narrow_yaml, prune_checkpoint

    with pytest.raises(ValueError, match="unknown activation"):
        narrow_yaml(0.125, 11, tmp_path / "yolov8n-x.yaml", act="gelu")
    wide = _random_model(0.25, tmp_path, 7)
    src = tmp_path / "wide.pt"
    torch.save({"model": wide, "ema": None}, src)
    out = prune_checkpoint(src, 0.25, tmp_path / "r.pt", tmp_path / "yolov8n-w0.25-relu.yaml", act="relu")
    m, _ = load_checkpoint(str(out))
    acts = {type(mod.act).__name__ for mod in m.modules() if hasattr(mod, "act") and hasattr(mod, "conv")}
    assert acts == {"ReLU"}
    for (k, a), b in zip(wide.state_dict().items(), m.state_dict().values()):  # same width: every weight kept
        assert torch.equal(a, b), k
