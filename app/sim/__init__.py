"""The pybullet side of the simulator, one concept per module; :mod:`app.sim_world` (``SimWorld``) is its facade.

- :mod:`app.sim.robot_model`: the TurtleBot3's geometry read from its URDF.
- :mod:`app.sim.render_worker`: camera rendering in a separate process.
"""
