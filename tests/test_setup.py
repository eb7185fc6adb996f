"""Back-end start-up: libLLVM discovery, variant choice, import hygiene."""
import os
import subprocess
import sys

import pytest

from skyfit_mi.errors import UnknownNameError
from skyfit_mi.render import variant


@pytest.mark.parametrize("name, version", [("libLLVM-19.so", 19), ("libLLVM.so.19.1", 19),
                                           ("libLLVM-14.0.6.so.1", 14), ("libLLVM-17.so.1", 17),
                                           ("libfoo.so", None)])
def test_llvm_version_from_file_name(name, version):
    assert variant.llvm_version_of("/usr/lib/" + name) == version


def test_a_usable_libllvm_is_found(mi):
    import drjit as dr
    path = variant.find_libllvm()
    assert path is not None and variant.llvm_version_of(path) >= variant.MIN_LLVM
    assert dr.detail.llvm_version()[0] >= variant.MIN_LLVM


def _python(code, env_extra=None):
    env = {k: v for k, v in os.environ.items() if k != "DRJIT_LIBLLVM_PATH"}
    env.update(env_extra or {})
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env)


def test_missing_libllvm_names_the_fix():
    r = _python("import skyfit_mi.render.variant as v\nv._LLVM_GLOBS = ()\n"
                "try:\n    v.setup()\nexcept v.SetupError as e:\n    print('ERR', e)\n")
    assert "ERR no libLLVM >= 17" in r.stdout and "apt-get install -y libllvm19" in r.stdout


def test_import_sets_no_variant():
    r = _python("import sys, skyfit_mi, skyfit_mi.physics.sky, skyfit_mi.physics.gensky, skyfit_mi.physics.ward, "
                "skyfit_mi.render, skyfit_mi.render.daylight, skyfit_mi.cli\n"
                "print('mitsuba' in sys.modules, 'drjit' in sys.modules)")
    assert r.stdout.split() == ["False", "False"], r.stderr


def test_unknown_and_unavailable_variants(mi):
    import drjit as dr
    with pytest.raises(UnknownNameError, match="'llvm_ad_rgb', 'cuda_ad_rgb'"):
        variant.setup("scalar_rgb")
    if dr.has_backend(dr.JitBackend.CUDA):
        pytest.skip("a CUDA GPU is present; its variant is usable here")
    with pytest.raises(variant.SetupError, match="use 'llvm_ad_rgb'"):
        variant.setup("cuda_ad_rgb")
