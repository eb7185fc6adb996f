"""skyfit-mi: daylight image sequences and Ward reflection-model fitting.

Importing this package never imports Mitsuba or sets a variant; the NumPy physics
(:mod:`skyfit_mi.physics`) works without a renderer.  Rendering starts with
:func:`skyfit_mi.render.setup`.
"""

__version__ = "0.1.0"
