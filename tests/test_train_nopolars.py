"""``scripts/train_detector_nopolars.py`` reads ultralytics' results.csv as polars does (column → values)."""

from __future__ import annotations

import importlib.util
from pathlib import Path
from types import SimpleNamespace

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _script():
    spec = importlib.util.spec_from_file_location("nopolars", ROOT / "scripts" / "train_detector_nopolars.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_results_csv_reads_as_columns_of_numbers(tmp_path: Path) -> None:
    csv = tmp_path / "results.csv"
    csv.write_text("epoch,time,train/box_loss,metrics/mAP50(B),lr/pg0\n1,12.5,1.25,0.9,6.67e-05\n2,24.0,1.2,0.91,5e-05\n")
    cols = _script()._read_results_csv(SimpleNamespace(csv=csv))
    assert cols == {"epoch": [1, 2], "time": [12.5, 24.0], "train/box_loss": [1.25, 1.2],
                    "metrics/mAP50(B)": [0.9, 0.91], "lr/pg0": [6.67e-05, 5e-05]}
    assert _script()._read_results_csv(SimpleNamespace(csv=tmp_path / "missing.csv")) == {}


def test_it_matches_polars_where_polars_is_installed(tmp_path: Path) -> None:
    pl = pytest.importorskip("polars")
    csv = tmp_path / "results.csv"
    csv.write_text("epoch,time,metrics/recall(B)\n1,3.25,0.5\n2,6.5,0.75\n")
    assert _script()._read_results_csv(SimpleNamespace(csv=csv)) == pl.read_csv(csv.read_bytes()).to_dict(as_series=False)
