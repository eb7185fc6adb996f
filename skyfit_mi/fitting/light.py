"""The fit's light: the options as given (:class:`LightOptions`), resolved against a sequence
before any tracing (:class:`LightPlan`), and traced by part (:class:`LightParts`), whose weights
the sky fit sets (:func:`~.sky_fit.fit_sky_scale`).
"""

from dataclasses import dataclass

import numpy as np

from ..errors import SkyfitError, check_choice, check_range
from ..physics.sky import SKY_CHOICES, SKY_LEVEL_SD
from ..pipeline.manifest import is_table
from ..render.basis_table import mixed
from .sky_fit import (check_terms, default_sky, default_sun_sd, photographed, shape_variants,
                      sun_source, sunlit)


@dataclass(frozen=True)
class LightPlan:
    """A fit's light resolved for a sequence (:meth:`LightOptions.resolve`).

    sky : 'spec' (as is), 'fit' (the sky's level fitted with the materials) or 'prior' (the same
        under :data:`~skyfit_mi.physics.sky.SKY_LEVEL_SD`)
    sun_sd, sun_source : the sun level's relative sd (of its log) in the reflectances' intervals,
        and its source: 'given' (``--sun-sd``), 'measured', 'modelled' or 'rendered'
    terms, shape, departure : ``--sky-terms`` (None: :func:`~.sky_fit.default_terms`),
        ``--sky-shape``, ``--sky-departure``
    """

    sky: str = "spec"
    sun_sd: float = 0.0
    sun_source: str = "given"
    terms: int = None
    shape: bool = False
    departure: bool = False

    @property
    def split(self):
        """Whether the sun's light and the rest of the sky's are traced apart (a fitted sky)."""
        return self.sky != "spec"

    @property
    def prior_sd(self):
        """The sd of the prior on log k (None: the level from the data alone)."""
        return SKY_LEVEL_SD if self.sky == "prior" else None

    def resolve(self, doc, skies, n_frames, log=print):
        """A plan is resolved already (as :meth:`LightOptions.resolve`): itself."""
        return self


#: The spec's light taken as it is.
SPEC_LIGHT = LightPlan()


@dataclass(frozen=True)
class LightOptions:
    """The light options of a fit as given (``fit --sky`` etc.); None chooses (:meth:`resolve`)."""

    sky: str = None
    sun_sd: float = None
    terms: int = None
    shape: bool = False
    departure: bool = None

    def resolve(self, doc, skies, n_frames, log=print):
        """The checked :class:`LightPlan` of these options on a sequence (manifest ``doc``,
        frames' ``skies``, ``n_frames``); Nones take :func:`~.sky_fit.default_sky` (logged),
        :func:`~.sky_fit.default_sun_sd`, and the departure on for photographs under a model sky."""
        sky, sun_sd, terms, shape = self.sky, self.sun_sd, self.terms, bool(self.shape)
        departure = self.departure
        if sky is not None:
            check_choice("sky", sky, SKY_CHOICES)
        if sun_sd is not None:
            check_range("--sun-sd", sun_sd, 0.0, 1.0)
        chosen = sky is None
        if chosen:
            sky = default_sky(doc, skies)
            if sky != "spec":
                log(f"sky: {'values measured' if is_table(doc) else 'photographs'} under the "
                    "sun and a sky: the spec's light is a model of theirs, so its level is "
                    f"fitted with its prior (--sky {sky}; --sky spec takes it as exact)")
        asked = terms not in (None, 1)
        if sky == "spec" and (asked or shape or sun_sd is not None or departure):
            given = ("--sky-terms" if asked else "--sky-shape" if shape else
                     "--sky-departure" if departure else "--sun-sd")
            raise SkyfitError(f"{given} belongs to a fitted sky, and the spec's is taken as it "
                              "is " + ("(the default where skyfit rendered the frames or no "
                                       "sun lights them)" if chosen else "(--sky spec)")
                              + ": give --sky fit or prior.")
        if sky == "spec":
            return SPEC_LIGHT
        if not sunlit(skies):                           # refused before the light is traced
            raise SkyfitError(f"--sky {sky} scales the sky against the sun, and no frame of the "
                              "sequence has the sun's disc above the horizon; fit with the "
                              "spec's sky (--sky spec).")
        if terms is not None:
            check_terms(terms, n_frames)
            terms = int(terms)
        if shape:
            shape_variants(skies)                       # refuses a sky without variants
        modelled = any(k.lit_by_sky for k in skies) and all(k.envmap is None for k in skies)
        if departure and not modelled:
            raise SkyfitError("--sky-departure moves a model sky's patterns, and the spec's "
                              "skies are maps (measured) or give no light but the sun's; leave "
                              "it out.")
        if departure is None:
            departure = photographed(doc) and modelled
            if departure:
                log("sky: photographs under a real sky, whose shape no model holds: its "
                    "departure from the spec's is fitted under its prior "
                    "(--no-sky-departure takes the spec's shape as exact)")
        departure = bool(departure)
        if sun_sd is not None:
            return LightPlan(sky, float(sun_sd), "given", terms, shape, departure)
        sun_sd = default_sun_sd(doc, skies)
        return LightPlan(sky, sun_sd, sun_source(skies) if sun_sd else "rendered", terms, shape,
                         departure)


@dataclass(frozen=True)
class LightParts:
    """The light at a region's points as traced, by part: radiance is linear in the light, so the
    parts' tables (thesis eq. 6.1) add with weights, L = sum_j w_j (rho_d D_j + s G_j)
    (:func:`~skyfit_mi.render.basis_table.mixed`).

    names : ``light`` (the spec's, alone), or ``sun``, ``sky``, ``shape:<index>`` and
        ``departure:<basis>``
    tables : each part's :class:`~skyfit_mi.render.basis_table.BasisTable`
    covariances : the parts' :class:`~skyfit_mi.render.basis_table.Covariances`, or None
    """

    names: tuple
    tables: tuple
    covariances: object = None

    @property
    def variants(self):
        """The parts mixed with the rest, in the mix's order (shape variants, then departure)."""
        return [n for n in self.names if n.startswith(("shape:", "departure:"))]

    @property
    def shapes(self):
        """How many of :attr:`variants` are shape variants (the first)."""
        return sum(n.startswith("shape:") for n in self.names)

    def subset(self, rows):
        """The parts at the points ``rows`` (a slice)."""
        return LightParts(self.names, tuple(t.subset(rows) for t in self.tables),
                          None if self.covariances is None else self.covariances.subset(rows))

    def table(self, k=1.0, mix=None, sun=1.0, tint=None):
        """The table with the sky ``k`` and the sun ``sun`` times the spec's (scalars or per frame),
        the sky's pattern (1 - sum(mix)) its own plus mix_j times variant j, the whole light
        times ``tint`` (3,) per channel (None: 1)."""
        if self.names == ("light",):
            return self.tables[0].tinted(tint)
        mix = np.zeros(len(self.variants)) if mix is None else np.asarray(mix, dtype=float)
        weights = {"sun": sun, "sky": k * (1.0 - mix.sum()),
                   **{v: k * m for v, m in zip(self.variants, mix)}}
        w = [weights[n] for n in self.names]
        return mixed(self.tables[0], self.tables[1:], w[1:], w[0], self.covariances, tint)
