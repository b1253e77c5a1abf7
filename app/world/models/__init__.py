"""The object model catalogue: every model a world file may name, as coloured parts.

:mod:`~app.world.models.catalogue` holds ``MODELS`` and ``get_model``; the models by kind are in
:mod:`~app.world.models.objects`, :mod:`~app.world.models.furniture` and :mod:`~app.world.models.fixtures`.
"""
