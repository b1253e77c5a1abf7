"""The world description: file format, validation and limits, random layouts, the model catalogue.

No pybullet here (the simulator is :mod:`app.sim_world`). Modules, lowest first:

- :mod:`app.world.models` — the object model catalogue (parts, models by kind, colours, meshes,
  footprints, pybullet bodies);
- :mod:`app.world.types` — ``World``, ``Wall``, ``Opening``, ``Obstacle``, ``WorldObject``, ``WorldError``;
- :mod:`app.world.validation` — limits and :func:`~app.world.validation.validate_world`;
- :mod:`app.world.format` — YAML: :func:`~app.world.format.load_world`, :func:`~app.world.format.dump_world`;
- :mod:`app.world.planner`, :mod:`app.world.rooms`, :mod:`app.world.furnish`, :mod:`app.world.layouts`,
  :mod:`app.world.generator` — random worlds: :func:`~app.world.generator.random_world`;
- :mod:`app.world.tour` — the tour check (which objects a route brings into view).
"""
