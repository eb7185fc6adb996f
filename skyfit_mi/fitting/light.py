"""The fit's light: what the user asked of it, checked once against a sequence, and the share of
each region's errors it carries.

Two records, the first stages of a fit (:mod:`~skyfit_mi.fitting.fit`):

* :class:`LightOptions`: ``fit --sky``, ``--sun-sd``, ``--sky-terms``, ``--sky-shape`` as
  given (region fits, ``--model auto`` and maps take the same record);
* :class:`LightPlan`: those options resolved against the sequence's manifest and skies before
  any light is traced (:meth:`LightOptions.resolve`): whether the sky is the spec's or fitted,
  with or without the level's prior, the sun level's uncertainty and where it comes from;
then the sky fit (:func:`~.sky_fit.fit_sky_scale`) returns what the light adds to each
region's errors (:class:`~.sky_fit.SkyShare`).
"""

from dataclasses import dataclass


from ..errors import SkyfitError, check_choice, check_range
from ..physics.sky import SKY_CHOICES, SKY_LEVEL_SD
from .sky_fit import (check_terms, default_sky, default_sun_sd, shape_variants, sun_source,
                      sun_up)


@dataclass(frozen=True)
class LightPlan:
    """A fit's light resolved for a sequence (:meth:`LightOptions.resolve`).

    sky : 'spec' (the spec's light as it is), 'fit' (the sky's level fitted against the sun's
        with the materials) or 'prior' (the same under the level's prior,
        :data:`~skyfit_mi.physics.sky.SKY_LEVEL_SD`)
    sun_sd : the sun's level's relative uncertainty (sd of its log) in the reflectances'
        intervals; ``sun_source`` where it comes from: 'given' (``--sun-sd``), 'measured' or
        'modelled' (the spec's sun), 'rendered' (the very sun skyfit rendered the day with)
    terms : the terms of the sky's level over the day (None: :func:`~.sky_fit.default_terms`)
    shape : whether the sky's shape variants are traced and mixed (``--sky-shape``)
    """

    sky: str = "spec"
    sun_sd: float = 0.0
    sun_source: str = "given"
    terms: int = None
    shape: bool = False

    @property
    def split(self):
        """Whether the sun's light and the rest of the sky's are traced apart (a fitted sky)."""
        return self.sky != "spec"

    @property
    def prior_sd(self):
        """The sd of the prior on log k (None: the level from the data alone)."""
        return SKY_LEVEL_SD if self.sky == "prior" else None


#: The spec's light taken as it is.
SPEC_LIGHT = LightPlan()


@dataclass(frozen=True)
class LightOptions:
    """The light options of a fit as given (``fit --sky``, ``--sun-sd``, ``--sky-terms``,
    ``--sky-shape``); None chooses (:meth:`resolve`)."""

    sky: str = None
    sun_sd: float = None
    terms: int = None
    shape: bool = False

    def resolve(self, doc, skies, n_frames, log=print):
        """The :class:`LightPlan` of these options on a sequence (its manifest ``doc``, its
        frames' ``skies``, ``n_frames`` fitted), checked before any light is traced: ``sky``
        None chosen (:func:`~.sky_fit.default_sky`, and said), ``sun_sd`` None its default
        (:func:`~.sky_fit.default_sun_sd`)."""
        sky, sun_sd, terms, shape = self.sky, self.sun_sd, self.terms, bool(self.shape)
        if sky is not None:
            check_choice("sky", sky, SKY_CHOICES)
        if sun_sd is not None:
            check_range("--sun-sd", sun_sd, 0.0, 1.0)
        chosen = sky is None
        if chosen:
            sky = default_sky(doc, skies)
            if sky != "spec":
                log(f"sky: photographs under the sun and a sky: the spec's light is a model of "
                    f"theirs, so its level is fitted with its prior (--sky {sky}; --sky spec "
                    "takes it as exact)")
        asked = terms not in (None, 1)
        if sky == "spec" and (asked or shape or sun_sd is not None):
            given = "--sky-terms" if asked else "--sky-shape" if shape else "--sun-sd"
            raise SkyfitError(f"{given} belongs to a fitted sky, and the spec's is taken as it "
                              "is " + ("(the default where skyfit rendered the frames or no "
                                       "sun lights them)" if chosen else "(--sky spec)")
                              + ": give --sky fit or prior.")
        if sky == "spec":
            return SPEC_LIGHT
        if not sun_up(skies):                           # refused before the light is traced
            raise SkyfitError(f"--sky {sky} scales the sky against the sun, and no frame of the "
                              "sequence has the sun's disc above the horizon; fit with the "
                              "spec's sky (--sky spec).")
        if terms is not None:
            check_terms(terms, n_frames)
            terms = int(terms)
        if shape:
            shape_variants(skies)                       # refuses a sky without variants
        if sun_sd is not None:
            return LightPlan(sky, float(sun_sd), "given", terms, shape)
        sun_sd = default_sun_sd(doc, skies)
        return LightPlan(sky, sun_sd, sun_source(skies) if sun_sd else "rendered", terms, shape)
