"""``ocslam train-detector`` where ultralytics' ``polars`` is not installed.

ultralytics reads its ``results.csv`` with polars for one thing during training: to store the epoch
table in every checkpoint (``BaseTrainer.read_results_csv``; plots, which also use it, are off in our
runs). A machine with no package registry (a lent GPU machine with torch but no polars, whose runtime
wheel is 54 MB) can still train: this reads that table with the standard ``csv`` module instead and
then runs the command unchanged.

    python scripts/train_detector_nopolars.py --resume --device 0 --data A --data B ...
"""

from __future__ import annotations

import csv
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def _read_results_csv(self) -> dict[str, list]:
    """The same dict polars' ``read_csv(...).to_dict(as_series=False)`` gives: column → values."""
    try:
        with open(self.csv, newline="") as f:
            rows = list(csv.reader(f))
    except OSError:
        return {}
    if not rows:
        return {}
    head = [h.strip() for h in rows[0]]
    cols: dict[str, list] = {h: [] for h in head}
    for row in rows[1:]:
        for h, v in zip(head, row):
            try:
                cols[h].append(float(v) if "." in v or "e" in v.lower() else int(v))
            except ValueError:
                cols[h].append(v.strip())
    return cols


def main() -> int:
    from app.config import PROJECT_ROOT
    from app.training.train import setup_offline

    setup_offline(PROJECT_ROOT / ".yolo")
    try:
        import polars  # noqa: F401
    except ImportError:
        from ultralytics.engine.trainer import BaseTrainer

        BaseTrainer.read_results_csv = _read_results_csv  # type: ignore[method-assign]
    from app.server import main as ocslam

    sys.argv = ["ocslam", "train-detector", *sys.argv[1:]]  # the model card records the command
    return int(ocslam(sys.argv[1:]) or 0)


if __name__ == "__main__":
    raise SystemExit(main())
