"""The project's Mitsuba plugins; :func:`register_plugins` registers them once a variant is set."""


def register_plugins():
    """Register ``cie_sky`` (emitter) and ``ward`` (BSDF) with the current variant."""
    import mitsuba as mi

    from .cie_sky import CIESkyEmitter
    from .ward import WardBSDF

    mi.register_emitter("cie_sky", lambda props: CIESkyEmitter(props))
    mi.register_bsdf("ward", lambda props: WardBSDF(props))
