"""Which Mitsuba variant pecs picks (pecs._mitsuba), with a stand-in Mitsuba whose variants
start or fail as a machine's would: CUDA first where a GPU is usable, LLVM where a libLLVM >= 16
is found, scalar with a warning otherwise."""

from __future__ import annotations

import sys
import types
import warnings

import pytest
from pecs import _mitsuba


def stand_in(monkeypatch: pytest.MonkeyPatch, working: set[str]) -> list[str]:
    """A fake `mitsuba` (and `drjit`) in which only the `working` variants start; returns the
    list of variants pecs tried, in order."""
    tried: list[str] = []
    fake = types.ModuleType("mitsuba")

    def set_variant(name: str) -> None:
        tried.append(name)
        if name not in working:
            raise ImportError(f"variant {name} is not available here")
        fake.variant = name

    fake.set_variant = set_variant
    fake.Float = float
    drjit = types.ModuleType("drjit")
    drjit.eval = lambda *_: None
    monkeypatch.setitem(sys.modules, "mitsuba", fake)
    monkeypatch.setitem(sys.modules, "drjit", drjit)
    monkeypatch.delenv("PECS_MITSUBA_VARIANT", raising=False)
    return tried


def pick(monkeypatch: pytest.MonkeyPatch, libllvm: str | None) -> types.ModuleType:
    # Empty (not unset) so that monkeypatch restores the real value the code overwrites.
    monkeypatch.setenv("DRJIT_LIBLLVM_PATH", "")
    monkeypatch.setattr(_mitsuba, "find_libllvm", lambda: libllvm)
    return _mitsuba.mitsuba.__wrapped__()


def test_cuda_is_picked_first_where_it_starts(monkeypatch: pytest.MonkeyPatch) -> None:
    tried = stand_in(monkeypatch, {"cuda_ad_spectral", "llvm_ad_spectral", "scalar_spectral"})
    assert pick(monkeypatch, "libLLVM-19.so").variant == "cuda_ad_spectral"
    assert tried == ["cuda_ad_spectral"]


def test_without_a_gpu_llvm_is_picked_quietly(monkeypatch: pytest.MonkeyPatch) -> None:
    tried = stand_in(monkeypatch, {"llvm_ad_spectral", "scalar_spectral"})
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert pick(monkeypatch, "libLLVM-19.so").variant == "llvm_ad_spectral"
    assert tried == ["cuda_ad_spectral", "llvm_ad_spectral"]


def test_without_libllvm_scalar_is_picked_with_a_warning_that_says_why(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    tried = stand_in(monkeypatch, {"llvm_ad_spectral", "scalar_spectral"})
    with pytest.warns(RuntimeWarning, match="apt install libllvm19"):
        assert pick(monkeypatch, None).variant == "scalar_spectral"
    assert tried == ["cuda_ad_spectral", "scalar_spectral"]
