"""Tuning sweeps on Ray Tune (issue 16): ``ocslam sweep SPEC.yaml``.

Modules: ``spec`` (the sweep file, validated against the config's own bounds), ``suite`` (recordings made
once per world), ``trace`` (the SLAM's side of a recording, replayed so a trial runs only the
consciousness), ``trial`` (one configuration over the suite), ``tune`` (Ray Tune: scheduling, resume),
``results`` (the table, the best config), ``plots`` (PNG figures). docs/tuning.md has the how-to.
Ray is an optional extra (``pip install -e .[scale]``): only ``tune`` imports it.
"""
