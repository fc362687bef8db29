"""Import Mitsuba with the best spectral variant this machine can run.

Order: `cuda_ad_spectral` when an NVIDIA GPU is usable, `llvm_ad_spectral` when a libLLVM >= 16
is found (Dr.Jit's LLVM backend needs it; Debian's `libllvm19` works), else `scalar_spectral`
with a warning that says why and what to install. `PECS_MITSUBA_VARIANT` forces a variant.
"""

from __future__ import annotations

import glob
import os
import re
import warnings
from functools import cache
from types import ModuleType

SPECTRAL_VARIANTS = ("cuda_ad_spectral", "llvm_ad_spectral", "scalar_spectral")
_MIN_LLVM_MAJOR = 16
_LLVM_GLOBS = (
    "/usr/lib/x86_64-linux-gnu/libLLVM*.so*",
    "/usr/lib/aarch64-linux-gnu/libLLVM*.so*",
    "/usr/lib/llvm-*/lib/libLLVM*.so*",
    "/usr/lib64/libLLVM*.so*",
    "/usr/local/lib/libLLVM*.so*",
    "/opt/homebrew/opt/llvm/lib/libLLVM.dylib",
    "/usr/local/opt/llvm/lib/libLLVM.dylib",
)


def find_libllvm() -> str | None:
    """Path of the newest libLLVM >= 16 on this machine, or None."""
    best: tuple[int, str] | None = None
    for pattern in _LLVM_GLOBS:
        for path in glob.glob(pattern):
            major = _llvm_major(path)
            if major is not None and major >= _MIN_LLVM_MAJOR and (best is None or major > best[0]):
                best = (major, path)
    return None if best is None else best[1]


def _llvm_major(path: str) -> int | None:
    match = re.search(r"(?:llvm-|LLVM-|LLVM\.so\.|LLVM-?)(\d+)", path)
    if match is None and path.endswith(".dylib"):
        return _MIN_LLVM_MAJOR  # Homebrew ships a current LLVM under an unversioned name
    return int(match.group(1)) if match else None


@cache
def mitsuba(variant: str | None = None) -> ModuleType:
    """Mitsuba, imported once, with `variant` (or the best spectral variant) set."""
    libllvm = os.environ.get("DRJIT_LIBLLVM_PATH") or find_libllvm()
    if libllvm:
        os.environ["DRJIT_LIBLLVM_PATH"] = libllvm
    import mitsuba as mi

    wanted = variant or os.environ.get("PECS_MITSUBA_VARIANT")
    if wanted:
        mi.set_variant(wanted)
        return mi
    reasons = []
    for candidate in SPECTRAL_VARIANTS:
        if candidate == "llvm_ad_spectral" and not libllvm:
            reasons.append(
                f"no libLLVM >= {_MIN_LLVM_MAJOR} found (on Debian/Ubuntu: apt install libllvm19)"
            )
            continue
        try:
            mi.set_variant(candidate)
            _smoke_test(mi)
        except Exception as error:  # a variant that cannot start says why in the warning
            reasons.append(
                f"{candidate}: {str(error).splitlines()[0] if str(error) else type(error).__name__}"
            )
            continue
        if candidate == "scalar_spectral":
            warnings.warn(
                "pecs renders with Mitsuba's slow scalar_spectral variant: " + "; ".join(reasons),
                RuntimeWarning,
                stacklevel=2,
            )
        return mi
    raise RuntimeError("no Mitsuba spectral variant could start: " + "; ".join(reasons))


def _smoke_test(mi: ModuleType) -> None:
    """Fail early when a JIT variant is selectable but its backend cannot run."""
    import drjit as dr

    dr.eval(mi.Float(1.0) + 1.0)
