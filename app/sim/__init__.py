"""The pybullet side of the simulator, one concept per module; :mod:`app.sim_world` (``SimWorld``) is its facade.

- :mod:`app.sim.renderer`: the camera renderer's choice (``sim.renderer``: EGL where it loads, else
  TinyRenderer), the EGL probe in a child process, and the EGL plugin's plumbing (quiet C stdout, mesh
  aliases).
- :mod:`app.sim.building`: a world loaded into a pybullet client (floor, walls with
  their openings, obstacles, objects, the robot and its collision probe).
- :mod:`app.sim.drive`: the kinematic differential drive (motor lag, wheel slip, collision refusal).
- :mod:`app.sim.lidar`: the planar LIDAR (:class:`~app.sim.lidar.PlanarCaster`, or pybullet ray tests).
- :mod:`app.sim.camera`: rendering a camera frame (RGB, depth, segmentation) and its pixel noise.
- :mod:`app.sim.ground_truth`: the world's objects and obstacles as ground-truth messages.
- :mod:`app.sim.robot_model`: the TurtleBot3's geometry read from its URDF.
- :mod:`app.sim.render_worker`: camera rendering in a separate process.
"""
