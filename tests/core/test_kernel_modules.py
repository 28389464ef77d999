"""``compile-kernels`` (run by the set-up command) covers every module that holds a Warp kernel,
so the first bake after set-up compiles nothing."""
from pathlib import Path

from radiosity_baker.core import device

CORE = Path(device.__file__).resolve().parent


def test_every_module_with_a_kernel_is_compiled_ahead():
    holding = {str(p.relative_to(CORE).with_suffix("")).replace("/", ".")
               for p in CORE.rglob("*.py") if "@wp.kernel" in p.read_text()}
    missing = holding - set(device.KERNEL_MODULES)
    assert not missing, f"add to device.KERNEL_MODULES: {sorted(missing)}"
    assert set(device.KERNEL_MODULES) <= holding  # no name left over after a kernel moved
