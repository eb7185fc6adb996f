"""The project's Mitsuba plugins; :func:`register_plugins` registers them once a variant is set."""


def register_plugins():
    """Register ``cie_sky``, ``ward`` and ``sun_sky_path`` with the current variant."""
    import mitsuba as mi

    # each plugin module subclasses the variant's Mitsuba classes: imported once it is set
    from .cie_sky import CIESkyEmitter
    from .sun_sky_path import SunSkyPathIntegrator
    from .ward import WardBSDF

    mi.register_emitter("cie_sky", lambda props: CIESkyEmitter(props))
    mi.register_bsdf("ward", lambda props: WardBSDF(props))
    mi.register_integrator("sun_sky_path", lambda props: SunSkyPathIntegrator(props))
