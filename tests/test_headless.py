"""A short headless end-to-end run: the same loop as the app, no browser, summary against ground truth."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from app.commands.run import run_headless
from app.config import Config

REQUIRED = ("sim_time_s", "wall_time_s", "real_time_factor", "distance_m", "odom_final_error_m", "odom_rms_error_m",
            "odom_final_heading_error_deg", "slam_ate_rmse_m", "map_precision", "map_recall")


def test_20s_headless_run_writes_config_and_summary(tmp_path: Path) -> None:
    cfg = Config.load(None, ["detector.kind=none"])
    rc = run_headless(cfg, route="tour", duration=20.0, out=tmp_path, quiet=True)
    assert rc == 0
    summary = json.loads((tmp_path / "summary.json").read_text())
    for k in REQUIRED:
        assert k in summary, k
    assert summary["sim_time_s"] == pytest.approx(20.0, abs=0.05)
    assert summary["distance_m"] > 1.0  # the route follower drove
    assert summary["collisions"] == 0
    # wheel odometry drifts a little; SLAM does better than a few cm on 20 s
    assert 0.0 < summary["odom_final_error_m"] < 0.3
    assert summary["slam_ate_rmse_m"] < 0.05
    assert summary["map_precision"] > 0.8 and summary["map_recall"] > 0.5
    again = Config.load(tmp_path / "config.yaml")
    assert again.to_dict() == cfg.to_dict()
    assert (tmp_path / "map.yaml").is_file() and (tmp_path / "trajectory_slam.tum").is_file()


@pytest.mark.slow
def test_ctrl_c_ends_cleanly_and_still_writes_the_summary(tmp_path: Path) -> None:
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    proc = subprocess.Popen(
        [sys.executable, "-m", "app", "run", "--headless", "--detector", "none", "--explore", "--duration", "1800",
         "--out", str(tmp_path)],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, env=env,
    )
    try:
        # the run directory is written as a unit at the end: wait for the progress bar (the loop runs)
        import select

        seen, deadline = b"", time.time() + 120
        while b"sim s" not in seen and time.time() < deadline and proc.poll() is None:
            if select.select([proc.stdout], [], [], 0.5)[0]:
                seen += os.read(proc.stdout.fileno(), 4096)
        assert not (tmp_path / "summary.json").exists()  # nothing written before the end
        time.sleep(1.0)  # let it drive a little (the apartment's exploration takes minutes of sim time)
        proc.send_signal(signal.SIGINT)
        out, _ = proc.communicate(timeout=120)
    finally:
        proc.kill()
    assert proc.returncode == 130, out.decode(errors="replace")[-2000:]
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["end_reason"] == "interrupted"
    assert 0 < summary["sim_time_s"] < 1800
    assert sorted(p.name for p in tmp_path.parent.iterdir() if p.name.startswith(f".{tmp_path.name}.")) == []
