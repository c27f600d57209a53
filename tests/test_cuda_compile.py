"""Every Warp kernel module compiles for CUDA (sm_90 PTX through NVRTC), GPU or not, so a
CUDA-only mistake (a construct the CPU backend accepts and nvcc's front end refuses) fails
here instead of on a user's GPU."""

import importlib
import pkgutil

import pytest
import warp as wp

import dpom_warp.kernels as kernels


def kernel_modules():
    names = [f"{kernels.__name__}.{m.name}" for m in pkgutil.iter_modules(kernels.__path__)]
    mods = [importlib.import_module(n) for n in names]
    return [m for m in mods if any(isinstance(v, wp.Kernel) for v in vars(m).values())]


def test_every_kernel_module_is_listed():
    names = {m.__name__.rsplit(".", 1)[1] for m in kernel_modules()}
    assert {"masks", "mean_field", "background", "sparse"} <= names


@pytest.mark.parametrize("module", kernel_modules(), ids=lambda m: m.__name__.rsplit(".", 1)[1])
def test_kernel_module_compiles_for_cuda(module, tmp_path):
    from warp._src import context

    if not context.runtime.nvrtc_supported_archs:
        pytest.skip("this Warp build has no NVRTC (CUDA compilation unavailable)")
    files = wp.compile_aot_module(module, arch=90, use_ptx=True, module_dir=tmp_path)
    ptx = [p for p in files if str(p).endswith(".ptx")]
    assert ptx, f"no PTX written for {module.__name__}: {files}"
    text = ptx[0].read_text()
    kernels_here = [v.key for v in vars(module).values() if isinstance(v, wp.Kernel)]
    for key in kernels_here:
        assert key in text, f"kernel {key} missing from the PTX of {module.__name__}"
