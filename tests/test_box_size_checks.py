"""The box-size checks of an area's islands (``area_candidate``): a box and an island are one object only when the
box, at the island's range, is as large as some instance of its class."""

from __future__ import annotations

from app.ocslam.se2 import Pose2


def _boxed_six_frames(label: str, shape, **switches) -> tuple[list[str], dict[str, int], float]:
    """Six frames of one box of ``label`` around ``shape`` (the robot creeping towards it) with the consciousness'
    ``switches`` set: the sources of the final ``label`` objects, the islands' rejection reasons counted, and the
    boxes' highest top row (px) over the frames' margin of a box cut by the image's top (``edge_margin_px``)."""
    from synthetic_scene import default_camera, detection, detections, raycast

    from app.ocslam.config import ConsciousnessConfig
    from app.ocslam.consciousness import Consciousness

    cam = default_camera()
    cfg = ConsciousnessConfig()
    for k, v in switches.items():
        setattr(cfg, k, v)
    c = Consciousness(cfg, cam)
    rejected: dict[str, int] = {}
    top = float("inf")
    for i in range(6):
        T = Pose2(0.03 * i, 0.05 * i, 0.0)
        det = detection(label, shape, T, cam, 0.95)
        assert det is not None
        top = min(top, det.y1 / cfg.edge_margin_px)
        rep = c.update(detections([det], cam), raycast([shape], T, cam), T, stamp=0.2 * i)
        for k, v in rep.rejected.items():
            rejected[k] = rejected.get(k, 0) + v
    return [t.source for t in c._tracks if t.label == label], rejected, top


def _assert_the_top_edge_decides(label: str, shape, switch: str) -> None:
    """``shape`` boxed as ``label`` in six frames, its box's top inside the image in each: with ``switch`` on, the
    top-edge check turns its island down in every frame (``corner_top``) and no object is made of it; with it off,
    neither that check nor the box-height check fires, and the island makes a ``label``."""
    found = {}
    for on in (True, False):
        sources, rejected, top = _boxed_six_frames(label, shape, **{switch: on})
        assert top > 2  # its top is in the image, in every frame
        found[on] = (sources, rejected.get("corner_top", 0), rejected.get("corner_short", 0))
    assert found[True][1] >= 6 and "lidar_island" not in found[True][0]
    assert found[False][1] == 0 and found[False][2] == 0 and "lidar_island" in found[False][0]


def test_a_box_lower_than_its_class_does_not_take_the_island():
    """A 0.45 m stool boxed as a shelf (the detector's mistake): at the stool's range the box is 0.45 m high, lower
    than any shelf (≥ 0.9 m, over the size tolerance), so its island is no shelf's (``corner_short``); without the
    check the stool's island makes a shelf."""
    from synthetic_scene import Box

    stool = Box(2.0, 0.0, 0.4, 0.4, 0.0, 0.0, 0.45)
    found = {}
    for check in (True, False):
        # the height check alone
        sources, rejected, _top = _boxed_six_frames("shelf", stool, box_height_check=check, top_edge_check=False)
        found[check] = (sources, rejected.get("corner_short", 0))
    assert found[True][1] >= 6 and "lidar_island" not in found[True][0]
    assert found[False][1] == 0 and "lidar_island" in found[False][0]


def test_a_box_whose_top_edge_is_lower_than_its_class_does_not_take_the_island():
    """A 1.2 m cabinet boxed as a door (the detector's mistake), its top inside the image: at the cabinet's range
    (a door's top stands above its front), and even read as deep as the deepest door, the box's top edge is at most
    1.4 m above the floor, lower than any door (≥ 1.6 m), so its island is no door's (``corner_top``). The box's
    height alone (1.2 m) passes the height check's tolerance; without the top-edge check the cabinet makes a door."""
    from synthetic_scene import Box

    _assert_the_top_edge_decides("door", Box(3.2, 0.0, 0.4, 0.8, 0.0, 0.0, 1.2), "top_edge_check")


def test_a_counter_boxed_as_a_shelf_is_read_at_its_front():
    """A 0.75 m kitchen counter boxed as a shelf at 3 m, its top inside the image. A bookcase's highest point stands
    above its front (``ClassPrior.top_at_front``), so the box's top row is read at the counter's front: 0.8 m, lower
    than any shelf (≥ 0.9 m), and the island is no shelf's (``corner_top``). Read as deep as the deepest shelf (0.7 m
    farther back, as for a chair's back) the row passes, and the box's height (0.75 m) passes the height check's
    tolerance: without ``top_edge_front`` the counter makes a shelf."""
    from synthetic_scene import Box

    _assert_the_top_edge_decides("shelf", Box(3.3, 0.0, 0.6, 1.6, 0.0, 0.0, 0.75), "top_edge_front")
