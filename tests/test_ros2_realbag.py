"""Replay of a real robot's ROS 1 bag (../shared/datasets/hw2-bag: 73 s, upside-down 360-beam LIDAR, wheel
odometry, no camera): the map agrees with the bag's own gridmap.png (free area and wall length within 20 %).
Skipped when the dataset is absent; it is read in place, never copied."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import ndimage

from app.config import PROJECT_ROOT, Config
from app.ros2.reader import read_bag
from app.ros2.replay import ReplayCore

HW2 = PROJECT_ROOT.parent / "shared" / "datasets" / "hw2-bag"
BAG = HW2 / "hw2_data.bag"
pytestmark = [pytest.mark.slow, pytest.mark.skipif(not BAG.is_file(), reason="../shared/datasets/hw2-bag is absent")]

#: config.yaml's tf_laser2robot [[-1,0,0,0.2],[0,1,0,0],[0,0,-1,0]]: a 180° turn about y, 0.2 m forward
T_BASE_SCAN = [0.2, 0.0, 0.0, 0.0, math.pi, 0.0]
RES = 0.05
OCC_P, FREE_P = 0.65, 0.196  # map_server's thresholds


def map_figures(occupied: np.ndarray, free: np.ndarray, res: float = RES, coarse: float = 0.2) -> tuple[float, float]:
    """(free area m², wall length m) of a grid: walls are occupied cells within two cells of free space,
    counted on a ``coarse`` grid so that a wall's thickness does not count as length."""
    wall = occupied & ndimage.binary_dilation(free, iterations=2)
    k = int(round(coarse / res))
    h, w = (wall.shape[0] // k) * k, (wall.shape[1] // k) * k
    cells = wall[:h, :w].reshape(h // k, k, w // k, k).any(axis=(1, 3))
    return float(free.sum() * res * res), float(cells.sum() * coarse)


def reference_figures() -> tuple[float, float]:
    import cv2

    g = cv2.imread(str(HW2 / "gridmap.png"), cv2.IMREAD_GRAYSCALE).astype(float)
    p = (255.0 - g) / 255.0
    return map_figures(p > OCC_P, p < FREE_P)


@pytest.fixture(scope="module")
def replay() -> ReplayCore:
    cfg = Config()
    cfg.set("replay.T_base_scan", T_BASE_SCAN)
    bag = read_bag(BAG)
    core = ReplayCore(cfg, bag)
    core.run()
    return core


def test_bag_is_read_as_described(replay):
    bag = replay.bag
    assert bag.topic_counts == {"/scan": 554, "/odom": 1508}
    assert 73.0 < bag.duration_s < 74.0 and bag.time_offset > 1.5e9
    assert any("no camera topic" in w for w in bag.warnings)
    assert replay.extrinsic_source == "config replay.T_base_scan" and not replay.scan_is_level
    assert replay.state.counters.scans == 554 and not replay.state.counters.errors


def test_map_agrees_with_the_bags_gridmap(replay):
    g = replay.slam.occupancy_grid(budget=10**9)
    d = g.data.astype(float)
    known = d >= 0
    ours = map_figures(known & (d / 100.0 > OCC_P), known & (d / 100.0 < FREE_P))
    ref = reference_figures()
    assert ref[0] > 50 and ref[1] > 40  # the reference is a room of ~60 m² (guards the figures themselves)
    assert abs(ours[0] - ref[0]) <= 0.2 * ref[0], (ours, ref)
    assert abs(ours[1] - ref[1]) <= 0.2 * ref[1], (ours, ref)


def test_ignoring_the_upside_down_mount_breaks_the_map(replay):
    cfg = Config()
    cfg.set("replay.T_base_scan", [0.2, 0.0, 0.0, 0.0, 0.0, 0.0])  # level: the scan is not mirrored
    bag = read_bag(BAG)
    bag.events = [e for e in bag.events if e.t <= bag.events[0].t + 30.0]
    wrong = ReplayCore(cfg, bag)
    wrong.run()
    good = ReplayCore(replay.cfg, read_bag(BAG))
    good.run_until(good.t_start + 30.0)

    def walls(core):
        d = core.slam.occupancy_grid(budget=10**9).data.astype(float)
        return map_figures((d >= 0) & (d / 100 > OCC_P), (d >= 0) & (d / 100 < FREE_P))[1]

    # unmirrored scans do not line up: the map's walls are far from the levelled replay's (here: mostly lost)
    assert abs(walls(wrong) - walls(good)) > 0.3 * walls(good)
