"""skyfit-mi: daylight image sequences and Ward reflection-model fitting.

Importing this package never imports Mitsuba or sets a variant; the NumPy
physics (:mod:`skyfit_mi.physics.sun`, :mod:`skyfit_mi.physics.sky`, :mod:`skyfit_mi.physics.ward`,
:mod:`skyfit_mi.physics.gensky`) works without a renderer.  Rendering starts with
:func:`skyfit_mi.render.setup`.
"""

__version__ = "0.1.0"
