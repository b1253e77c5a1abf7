"""map_server YAML + PGM: round trip, conventions, atomic writes and clear errors."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from app.ocslam.mapio import MapIOError, decode_pgm, load_map, save_map
from app.ocslam.messages import OccupancyGrid
from app.ocslam.se2 import Pose2


def _grid():
    data = np.full((4, 6), -1, np.int8)
    data[0, :] = 0  # bottom row free
    data[1, 2] = 100  # one occupied cell
    data[2, 3] = 70  # above occupied_thresh
    data[3, 0] = 10  # below free_thresh
    data[3, 1] = 50  # in between: unknown in trinary
    return OccupancyGrid(0.05, Pose2(-1.5, 2.25, 0.0), data)


def test_round_trip_and_conventions(tmp_path):
    g = _grid()
    yp = save_map(g, tmp_path / "sub" / "map.yaml")
    meta = yaml.safe_load(yp.read_text())
    assert meta["image"] == "map.pgm"
    assert meta["resolution"] == 0.05
    assert meta["origin"] == [-1.5, 2.25, 0.0]
    assert meta["negate"] == 0 and meta["mode"] == "trinary"
    assert meta["occupied_thresh"] == 0.65 and meta["free_thresh"] == 0.196
    img = decode_pgm((tmp_path / "sub" / "map.pgm").read_bytes())
    assert img.shape == (4, 6)
    # PGM row 0 is the top of the map = OccupancyGrid's last row
    assert img[3, 0] == 254 and img[2, 2] == 0 and img[0, 0] == 254 and img[0, 1] == 205 and img[3, 5] == 254
    back = load_map(yp)
    assert back.resolution == 0.05 and back.origin == Pose2(-1.5, 2.25, 0.0)
    expected = np.full((4, 6), -1, np.int8)
    expected[g.data == 0] = 0
    expected[g.data == 10] = 0
    expected[g.data == 100] = 100
    expected[g.data == 70] = 100
    assert np.array_equal(back.data, expected)
    # a trinary grid survives a second round trip unchanged
    yp2 = save_map(back, tmp_path / "again.yaml")
    assert np.array_equal(load_map(yp2).data, back.data)
    # no temporary files are left behind
    assert sorted(p.name for p in (tmp_path / "sub").iterdir()) == ["map.pgm", "map.yaml"]


def test_world_to_cell_agrees_after_round_trip(tmp_path):
    g = _grid()
    back = load_map(save_map(g, tmp_path / "m.yaml"))
    p = np.array([[-1.5 + 2.5 * 0.05, 2.25 + 1.5 * 0.05]])  # centre of cell (row 1, col 2): occupied
    r, c = back.world_to_cell(p)[0]
    assert back.data[r, c] == 100


def test_errors(tmp_path):
    with pytest.raises(MapIOError, match="cannot read map"):
        load_map(tmp_path / "missing.yaml")
    (tmp_path / "bad.yaml").write_text("image: x.pgm\nresolution: 0.05\n")
    with pytest.raises(MapIOError, match="origin"):
        load_map(tmp_path / "bad.yaml")
    (tmp_path / "noimg.yaml").write_text("image: x.pgm\nresolution: 0.05\norigin: [0, 0, 0]\n")
    with pytest.raises(MapIOError, match="cannot read map image"):
        load_map(tmp_path / "noimg.yaml")
    (tmp_path / "x.pgm").write_bytes(b"P5\n10 10\n255\n" + b"\x00" * 5)
    with pytest.raises(MapIOError, match="expected 100"):
        load_map(tmp_path / "noimg.yaml")
    blocker = tmp_path / "file"
    blocker.write_text("not a directory")
    with pytest.raises(MapIOError, match="cannot save map"):
        save_map(_grid(), blocker / "map.yaml")


def test_ascii_pgm_and_comments():
    img = decode_pgm(b"P2\n# a comment\n3 2\n255\n0 254 205\n205 0 254\n")
    assert img.tolist() == [[0, 254, 205], [205, 0, 254]]
