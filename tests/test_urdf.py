"""The TurtleBot3 Burger URDF: loads in yourdfpy, pybullet and viser, REP-103 frames, meshes, physics."""

from __future__ import annotations

import importlib.util
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pybullet as p
import pytest
import yourdfpy

from app.ocslam.messages import CameraInfo
from app.sim.robot_model import DEFAULT_URDF, RobotModel, link_poses

ROOT = Path(__file__).resolve().parents[1]
MESH_DIR = ROOT / "assets" / "meshes" / "turtlebot3"

LINKS = {
    "base_footprint",
    "base_link",
    "wheel_left_link",
    "wheel_right_link",
    "caster_back_link",
    "base_scan",
    "camera_link",
    "camera_optical_frame",
}
PARENT = {  # child -> parent
    "base_link": "base_footprint",
    "wheel_left_link": "base_link",
    "wheel_right_link": "base_link",
    "caster_back_link": "base_link",
    "base_scan": "base_link",
    "camera_link": "base_link",
    "camera_optical_frame": "camera_link",
}
PB_FLAGS = p.URDF_USE_IMPLICIT_CYLINDER | p.URDF_USE_INERTIA_FROM_FILE


# --------------------------------------------------------------------------------------------------
# yourdfpy
# --------------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def urdf() -> yourdfpy.URDF:
    return yourdfpy.URDF.load(str(DEFAULT_URDF))  # loads the meshes through the default filename handler


def test_yourdfpy_links_joints_tree(urdf: yourdfpy.URDF) -> None:
    assert set(urdf.link_map) == LINKS
    assert urdf.base_link == "base_footprint"
    assert {j.child: j.parent for j in urdf.robot.joints} == PARENT
    assert urdf.actuated_joint_names == ["wheel_left_joint", "wheel_right_joint"]
    for name, child in (("wheel_left_joint", "wheel_left_link"), ("wheel_right_joint", "wheel_right_link")):
        j = urdf.joint_map[name]
        assert j.type == "continuous" and j.child == child
        np.testing.assert_allclose(j.axis, [0.0, 1.0, 0.0])
    others = [j for j in urdf.robot.joints if j.name not in ("wheel_left_joint", "wheel_right_joint")]
    assert all(j.type == "fixed" for j in others)


def test_yourdfpy_frame_heights(urdf: yourdfpy.URDF) -> None:
    poses = link_poses(urdf)  # base_footprint is the root, on the floor
    assert poses["base_link"][2, 3] == pytest.approx(0.010)
    assert poses["base_scan"][2, 3] == pytest.approx(0.173, abs=0.002)
    assert poses["camera_optical_frame"][2, 3] == pytest.approx(0.19, abs=0.01)
    # the LIDAR sits about 3 cm behind the wheel axle, the wheels on the axle at wheel-radius height
    assert -0.04 < poses["base_scan"][0, 3] < -0.025
    for side, y in (("left", 0.08), ("right", -0.08)):
        np.testing.assert_allclose(poses[f"wheel_{side}_link"][:3, 3], [0.0, y, 0.033], atol=1e-9)


def test_every_mesh_is_referenced_exists_and_is_small(urdf: yourdfpy.URDF) -> None:
    referenced = set()
    for link in urdf.robot.links:
        for vis in link.visuals:
            assert vis.geometry.mesh is not None, f"{link.name}: visual without a mesh"
            fn = vis.geometry.mesh.filename
            assert fn.startswith("../meshes/turtlebot3/") and fn.endswith(".obj"), fn
            path = (DEFAULT_URDF.parent / fn).resolve()
            assert path.is_file(), fn
            referenced.add(path.name)
            assert vis.material is not None and vis.material.name in urdf._material_map, link.name
    on_disk = {q.name for q in MESH_DIR.glob("*.obj")}
    assert referenced == on_disk  # nothing missing, nothing unused
    assert sum((MESH_DIR / n).stat().st_size for n in on_disk) < 400_000


def test_yourdfpy_scene_has_all_meshes_with_material_colours(urdf: yourdfpy.URDF) -> None:
    n_visuals = sum(len(link.visuals) for link in urdf.robot.links)
    assert n_visuals == 19
    assert len(urdf.scene.geometry) == n_visuals
    root = ET.parse(DEFAULT_URDF).getroot()
    rgba = {
        m.get("name"): [float(x) for x in m.find("color").get("rgba").split()]
        for m in root.findall("material")
    }
    expected = sorted(
        tuple(int(c) for c in np.array(rgba[v.material.name]) * 255)
        for link in urdf.robot.links
        for v in link.visuals
    )
    got = []
    for geom in urdf.scene.geometry.values():
        assert len(geom.faces) > 0
        colours = np.unique(geom.visual.face_colors, axis=0)
        assert len(colours) == 1  # one part, one colour
        got.append(tuple(int(c) for c in colours[0]))
    # yourdfpy (and so viser) shows the URDF material colours (±1 for 0..255 rounding)
    np.testing.assert_allclose(np.array(sorted(got)), np.array(expected), atol=1)
    # the scene's bounding box is the Burger: ~0.14 m long, 0.178 m wide, ~0.19 m tall (plus the camera)
    lo, hi = urdf.scene.bounds
    size = hi - lo
    assert lo[2] == pytest.approx(0.0, abs=1e-4)  # wheels and caster touch the floor
    assert 0.13 < size[0] < 0.16
    assert size[1] == pytest.approx(0.178, abs=0.003)
    assert 0.19 < size[2] < 0.21


def test_materials_are_coloured() -> None:
    root = ET.parse(DEFAULT_URDF).getroot()
    colours = {m.get("name"): m.find("color").get("rgba") for m in root.findall("material")}
    assert len(set(colours.values())) >= 8  # distinct parts have distinct colours
    for m in root.iter("material"):
        if m.find("color") is None:  # references
            assert m.get("name") in colours


def test_masses_and_inertias_are_sensible(urdf: yourdfpy.URDF) -> None:
    for link in urdf.robot.links:
        assert link.inertial is not None, f"{link.name} has no <inertial> (pybullet would give it 1 kg)"
        assert link.inertial.mass > 0
        assert np.all(np.linalg.eigvalsh(link.inertial.inertia) > 0)
    total = sum(link.inertial.mass for link in urdf.robot.links)
    assert 0.9 < total < 1.1  # the Burger weighs about 1 kg


# --------------------------------------------------------------------------------------------------
# pybullet
# --------------------------------------------------------------------------------------------------
@pytest.fixture()
def pb():
    cid = p.connect(p.DIRECT)
    yield cid
    p.disconnect(cid)


def _load(cid: int, flags: int = PB_FLAGS) -> int:
    return p.loadURDF(str(DEFAULT_URDF), flags=flags, physicsClientId=cid)


def _link_frames(cid: int, rid: int) -> dict[str, np.ndarray]:
    """URDF link frames (getLinkState[4:6], not the centre of mass) as (4, 4) poses in the world."""
    out = {}
    pos, orn = p.getBasePositionAndOrientation(rid, physicsClientId=cid)
    out[p.getBodyInfo(rid, physicsClientId=cid)[0].decode()] = _pose(pos, orn)
    for i in range(p.getNumJoints(rid, physicsClientId=cid)):
        name = p.getJointInfo(rid, i, physicsClientId=cid)[12].decode()
        st = p.getLinkState(rid, i, computeForwardKinematics=True, physicsClientId=cid)
        out[name] = _pose(st[4], st[5])
    return out


def _pose(pos, orn) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = np.asarray(p.getMatrixFromQuaternion(orn)).reshape(3, 3)
    T[:3, 3] = pos
    return T


def test_pybullet_links_joints_and_frames_match_yourdfpy(pb: int, urdf: yourdfpy.URDF) -> None:
    rid = _load(pb)
    joints = {}
    for i in range(p.getNumJoints(rid, physicsClientId=pb)):
        info = p.getJointInfo(rid, i, physicsClientId=pb)
        joints[info[1].decode()] = (info[2], info[12].decode(), np.asarray(info[13]))
    assert (
        joints["wheel_left_joint"][0] == p.JOINT_REVOLUTE
        and joints["wheel_left_joint"][1] == "wheel_left_link"
    )
    assert joints["wheel_right_joint"][0] == p.JOINT_REVOLUTE
    np.testing.assert_allclose(joints["wheel_left_joint"][2], [0, 1, 0])
    assert sum(1 for j in joints.values() if j[0] == p.JOINT_FIXED) == 5
    frames = _link_frames(pb, rid)
    assert set(frames) == LINKS
    # the base's pybullet pose is base_footprint's (its inertial origin is at its frame)
    ref = link_poses(urdf)
    for name in LINKS:
        np.testing.assert_allclose(frames[name], ref[name], atol=1e-6, err_msg=name)


def test_pybullet_finds_every_visual_mesh(pb: int, urdf: yourdfpy.URDF) -> None:
    rid = _load(pb)
    shapes = p.getVisualShapeData(rid, physicsClientId=pb)
    assert len(shapes) == sum(len(link.visuals) for link in urdf.robot.links)
    assert all(s[2] == p.GEOM_MESH for s in shapes)
    colours = {tuple(np.round(s[7], 2)) for s in shapes}
    assert len(colours) >= 8  # the URDF materials reached pybullet


def test_pybullet_robot_rests_level_on_wheels_and_caster_and_drives(pb: int) -> None:
    p.setGravity(0, 0, -9.81, physicsClientId=pb)
    plane = p.createCollisionShape(p.GEOM_PLANE, physicsClientId=pb)
    p.createMultiBody(0, plane, physicsClientId=pb)
    rid = _load(pb)
    idx = {
        p.getJointInfo(rid, i, physicsClientId=pb)[1].decode(): i
        for i in range(p.getNumJoints(rid, physicsClientId=pb))
    }
    left, right = idx["wheel_left_joint"], idx["wheel_right_joint"]
    for _ in range(240):
        p.stepSimulation(physicsClientId=pb)
    pos, orn = p.getBasePositionAndOrientation(rid, physicsClientId=pb)
    roll, pitch, _ = p.getEulerFromQuaternion(orn)
    assert abs(pos[2]) < 5e-4 and abs(roll) < 2e-3 and abs(pitch) < 2e-3
    touching = {c[3] for c in p.getContactPoints(bodyA=rid, physicsClientId=pb)}
    assert touching == {left, right, idx["caster_back_joint"]}  # the two wheels and the caster, nothing else

    # both wheels at +ω: forward along +x (REP-103); right faster: turns left (+yaw, counter-clockwise)
    w = 0.2 / 0.033
    for j, v in ((left, w), (right, w)):
        p.setJointMotorControl2(rid, j, p.VELOCITY_CONTROL, targetVelocity=v, force=1.0, physicsClientId=pb)
    for _ in range(240):
        p.stepSimulation(physicsClientId=pb)
    pos, orn = p.getBasePositionAndOrientation(rid, physicsClientId=pb)
    assert pos[0] > 0.15 and abs(pos[1]) < 0.01
    yaw0 = p.getEulerFromQuaternion(orn)[2]
    for j, v in ((left, 0.5 * w), (right, 1.5 * w)):
        p.setJointMotorControl2(rid, j, p.VELOCITY_CONTROL, targetVelocity=v, force=1.0, physicsClientId=pb)
    for _ in range(120):
        p.stepSimulation(physicsClientId=pb)
    assert (
        p.getEulerFromQuaternion(p.getBasePositionAndOrientation(rid, physicsClientId=pb)[1])[2] > yaw0 + 0.3
    )


def test_scan_plane_is_free_of_robot_collision_geometry(pb: int) -> None:
    """Rays cast from base_scan's origin in its plane never hit the robot (the LIDAR sim relies on it)."""
    rid = _load(pb)
    T = _link_frames(pb, rid)["base_scan"]
    a = np.arange(360) * np.pi / 180
    dirs = np.stack([np.cos(a), np.sin(a), np.zeros_like(a)], axis=1) @ T[:3, :3].T
    origin = np.repeat(T[None, :3, 3], 360, axis=0)
    hits = p.rayTestBatch(origin.tolist(), (origin + 0.5 * dirs).tolist(), physicsClientId=pb)
    assert [h[0] for h in hits] == [-1] * 360
    # rays from 0.25 m outside towards the LIDAR's centre: none in the scan plane hits the robot, while
    # the same rays 1.2 cm lower (the LDS base) and 2 cm higher (the camera, ahead) do, so the check can fail
    outside = origin + 0.25 * dirs
    for dz, expect_hits in ((0.0, False), (-0.012, True), (0.02, True)):
        hits = p.rayTestBatch(
            (outside + [0, 0, dz]).tolist(), (origin + [0, 0, dz]).tolist(), physicsClientId=pb
        )
        n = sum(h[0] == rid for h in hits)
        assert (n > 0) == expect_hits, (dz, n)


def _render(cid: int, T_world_optical: np.ndarray, info: CameraInfo) -> np.ndarray:
    """Segmentation mask (H, W) of a pinhole camera at the optical frame (z forward, y down)."""
    eye = T_world_optical[:3, 3]
    view = p.computeViewMatrix(eye, eye + T_world_optical[:3, 2], -T_world_optical[:3, 1])
    vfov = np.degrees(2 * np.arctan(info.height / 2 / info.fy))
    proj = p.computeProjectionMatrixFOV(vfov, info.width / info.height, 0.01, 10.0)
    _, _, _, _, seg = p.getCameraImage(
        info.width, info.height, view, proj, renderer=p.ER_TINY_RENDERER, physicsClientId=cid
    )
    return np.asarray(seg).reshape(info.height, info.width)


def test_camera_sees_the_world_not_itself_and_matches_K_R_t(pb: int) -> None:
    """Render from camera_optical_frame: no robot pixels, and K[R|t] from RobotModel lands on a sphere."""
    robot = RobotModel.load()
    rid = _load(pb)
    info = CameraInfo.from_fov(320, 240, 1.04)
    ball_base = np.array([1.2, 0.25, 0.30])  # in base_footprint (robot at the world origin)
    vs = p.createVisualShape(p.GEOM_SPHERE, radius=0.03, physicsClientId=pb)
    bid = p.createMultiBody(0, -1, vs, basePosition=ball_base.tolist(), physicsClientId=pb)
    T_world_optical = _link_frames(pb, rid)["camera_optical_frame"]
    np.testing.assert_allclose(T_world_optical, robot.T_base_camera_optical, atol=1e-6)
    seg = _render(pb, T_world_optical, info)
    assert not np.any((seg & ((1 << 24) - 1)) == rid), "the camera sees the robot's own body"
    vv, uu = np.nonzero(seg == bid)
    assert len(uu) > 20
    p_opt = np.linalg.inv(robot.T_base_camera_optical) @ np.append(ball_base, 1.0)
    assert p_opt[2] > 1.0
    uv = (info.K @ p_opt[:3])[:2] / p_opt[2]
    np.testing.assert_allclose([uu.mean() + 0.5, vv.mean() + 0.5], uv, atol=1.5)
    assert uv[0] < info.cx and uv[1] < info.cy  # left of and above the centre: +y is left, +z is up

    # sanity: the same renderer does see the robot from a camera in front of it looking back
    T_front = np.eye(4)
    T_front[:3, :3] = np.array([[0, 0, -1], [1, 0, 0], [0, -1, 0]])  # optical z along -x
    T_front[:3, 3] = [0.6, 0.0, 0.12]
    assert np.any((_render(pb, T_front, info) & ((1 << 24) - 1)) == rid)


# --------------------------------------------------------------------------------------------------
# the mesh script
# --------------------------------------------------------------------------------------------------
def _triangles(path: Path) -> np.ndarray:
    """(F, 9) triangles of an OBJ file as vertex coordinates, in a canonical order.

    Each triangle starts at its smallest vertex (its winding is kept) and the rows are sorted, so two
    files with the same surface compare equal whatever order a trimesh/manifold version wrote them in.
    """
    v, faces = [], []
    for line in path.read_text().splitlines():
        if line.startswith("v "):
            v.append([float(x) for x in line.split()[1:4]])
        elif line.startswith("f "):
            faces.append([int(tok.split("/")[0]) - 1 for tok in line.split()[1:4]])
    tri = np.asarray(v)[np.asarray(faces)]  # (F, 3, 3)
    key = np.round(tri, 4)
    first = np.array([min(range(3), key=lambda i, t=t: tuple(t[i])) for t in key])
    tri = np.stack([np.roll(t, -f, axis=0) for t, f in zip(tri, first)]).reshape(-1, 9)
    return tri[np.lexsort(np.round(tri, 4).T[::-1])]


def test_mesh_script_reproduces_the_committed_meshes(tmp_path: Path) -> None:
    spec = importlib.util.spec_from_file_location(
        "make_robot_meshes", ROOT / "scripts" / "make_robot_meshes.py"
    )
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    for name, mesh in mod.build_meshes().items():
        assert mesh.is_watertight and mesh.volume > 0, (
            name
        )  # closed solids (the files split edges for shading)
    written = mod.write_meshes(tmp_path)
    assert {q.name for q in written} == {q.name for q in MESH_DIR.glob("*.obj")}
    for new in written:
        old = MESH_DIR / new.name
        if new.read_bytes() == old.read_bytes():
            continue
        # other trimesh/manifold versions may order faces differently or round the last digit:
        # compare the surfaces (every triangle, with its winding), not the files
        t_new, t_old = _triangles(new), _triangles(old)
        assert t_new.shape == t_old.shape, new.name
        np.testing.assert_allclose(t_new, t_old, atol=2e-5, err_msg=new.name)


# --------------------------------------------------------------------------------------------------
# viser
# --------------------------------------------------------------------------------------------------
def test_viser_urdf_loads_with_meshes() -> None:
    import viser
    from viser.extras import ViserUrdf

    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    try:
        root = server.scene.add_frame("/robot", show_axes=False)
        vu = ViserUrdf(server, DEFAULT_URDF, root_node_name="/robot")
        assert list(vu.get_actuated_joint_names()) == ["wheel_left_joint", "wheel_right_joint"]
        vu.update_cfg(np.zeros(2))
        vu.update_cfg(np.array([0.5, -0.5]))
        assert len(vu._meshes) == 19  # every visual mesh became a scene node
        root.position = (1.0, 2.0, 0.0)
    finally:
        server.stop()
