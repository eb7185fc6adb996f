"""What the tests and the scripts in ``scripts/`` use and a user of ``skyfit`` does not.

- :mod:`.photo_sim`: a rendered day photographed as a camera would (exposure, vignetting,
  noise, JPEG/DNG with EXIF); :mod:`.table_sim`: lab tables measured from a render.
- :mod:`.sky_measurement`: the measured clear day of Kider et al. 2014 (``../shared/data``),
  sky models compared against its scans; :mod:`.measured_sky` and :mod:`.sky_scans`: those scans
  as envmaps; :mod:`.sunsky_reference`: Mitsuba's ``sunsky`` as a sky model to compare.
- :mod:`.cramer_rao`: the Cramer-Rao bound that intervals are checked against.

It builds on :mod:`skyfit_mi`, never the other way round (tests/test_layers.py).
"""
