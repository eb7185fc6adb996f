"""The Mitsuba layer: the only part of skyfit-mi that imports mitsuba/drjit.

Call :func:`setup` first: it picks the variant and registers the project's plugins.
"""

from .variant import DEFAULT_VARIANT, VARIANTS, find_libllvm, setup

__all__ = ["DEFAULT_VARIANT", "VARIANTS", "find_libllvm", "setup"]
