"""Start Mitsuba: find libLLVM for the CPU back-end and choose the variant.

drjit 1.5 needs LLVM 17 or newer (14 lacks opaque pointers; 15/16 abort on llvm.minimum):
:func:`setup` sets ``DRJIT_LIBLLVM_PATH`` to :func:`find_libllvm`'s before the first ``import
drjit`` unless the user has.  Importing :mod:`skyfit_mi` never sets a variant: call :func:`setup`.
"""

import glob
import os
import re
import sys

from ..errors import SetupError, check_choice
from .plugins import register_plugins

MIN_LLVM = 17
#: Variants this project supports; the default is the CPU one.
VARIANTS = ("llvm_ad_rgb", "cuda_ad_rgb")
DEFAULT_VARIANT = "llvm_ad_rgb"
_LLVM_GLOBS = ("/usr/lib/x86_64-linux-gnu/libLLVM*.so*", "/usr/lib/aarch64-linux-gnu/libLLVM*.so*",
               "/usr/lib/llvm-*/lib/libLLVM*.so*", "/usr/lib64/libLLVM*.so*",
               "/usr/local/lib/libLLVM*.so*", "/opt/homebrew/opt/llvm/lib/libLLVM*.dylib")
FIX = ("install libLLVM 17 or newer (Debian/Ubuntu: `apt-get install -y libllvm19`, or run "
       "`bash scripts/install.sh`), or set DRJIT_LIBLLVM_PATH to such a libLLVM.so")


def llvm_version_of(path):
    """Major LLVM version in a libLLVM file name (libLLVM-19.so, libLLVM.so.19.1), or None."""
    m = re.search(r"libLLVM[-.]?(?:so\.)?(\d+)", os.path.basename(path))
    return int(m.group(1)) if m else None


def find_libllvm():
    """Path of the newest libLLVM >= 17 on this machine, or None."""
    found = {}
    for pattern in _LLVM_GLOBS:
        for path in glob.glob(pattern):
            v = llvm_version_of(path)
            if v is not None and v >= MIN_LLVM and os.path.isfile(path):
                found.setdefault(v, path)
    return found[max(found)] if found else None


def _prepare_llvm():
    if "DRJIT_LIBLLVM_PATH" in os.environ:
        return os.environ["DRJIT_LIBLLVM_PATH"]
    if "drjit" in sys.modules:   # too late to steer drjit; it reports itself below
        return None
    path = find_libllvm()
    if path is None:
        raise SetupError(f"no libLLVM >= {MIN_LLVM} was found for Mitsuba's CPU variant; {FIX}.")
    os.environ["DRJIT_LIBLLVM_PATH"] = path
    return path


def setup(variant=DEFAULT_VARIANT):
    """Choose the Mitsuba variant and register the project's plugins.

    ``variant``: ``llvm_ad_rgb`` (CPU, the default) or ``cuda_ad_rgb`` (an NVIDIA GPU and
    driver).  Returns the ``mitsuba`` module, with the variant set.
    """
    check_choice("Mitsuba variant", variant, VARIANTS)
    if variant.startswith("llvm"):
        _prepare_llvm()
    import drjit as dr
    import mitsuba as mi

    if variant.startswith("llvm") and not dr.has_backend(dr.JitBackend.LLVM):
        raise SetupError("Dr.Jit could not load a usable libLLVM "
                         f"(DRJIT_LIBLLVM_PATH={os.environ.get('DRJIT_LIBLLVM_PATH')!r}); {FIX}.")
    if variant.startswith("llvm"):
        major = dr.detail.llvm_version()[0]
        if major < MIN_LLVM:
            raise SetupError(f"Dr.Jit loaded LLVM {major}, which crashes drjit 1.5; {FIX}.")
    if variant.startswith("cuda") and not dr.has_backend(dr.JitBackend.CUDA):
        raise SetupError("variant 'cuda_ad_rgb' was asked for but no CUDA GPU/driver is usable "
                         "here; use 'llvm_ad_rgb' (the default) on this machine.")
    if mi.variant() != variant:
        mi.set_variant(variant)
    register_plugins()
    return mi
