"""The Mitsuba layer: the only part of skyfit-mi that imports mitsuba/drjit.

Call :func:`setup` first; it picks the variant (``llvm_ad_rgb`` by default)
and registers the ``cie_sky`` emitter and ``ward`` BSDF plugins.
"""

from .variant import DEFAULT_VARIANT, VARIANTS, find_libllvm, setup

__all__ = ["DEFAULT_VARIANT", "VARIANTS", "find_libllvm", "setup"]
