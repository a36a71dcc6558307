"""Finding a libLLVM for Dr.Jit, and choosing the variant."""

from __future__ import annotations

import os
import subprocess
import sys

import drjit as dr
import mitsuba as mi
import pytest

import mifaces
from mifaces.runtime import llvm


@pytest.mark.parametrize("path,version", [
    ("/venv/lib/libLLVM.so.23.1", 23),
    ("/usr/lib/x86_64-linux-gnu/libLLVM-15.so.1", 15),
    ("/usr/lib/llvm-19/lib/libLLVM.so", 19),
    ("/usr/lib/llvm-19/lib/libLLVM-19.so", 19),
    ("/opt/homebrew/opt/llvm@18/lib/libLLVM.dylib", 18),
    ("/somewhere/libLLVM.so", None),
])
def test_major_version_from_file_name(path, version):
    assert llvm._major_version(path) == version


def test_finds_a_recent_enough_libllvm_newest_first(monkeypatch, tmp_path):
    for name in ["libLLVM-14.so.1", "libLLVM-15.so.1", "libLLVM-17.so.1", "libLLVM.so.21.1"]:
        (tmp_path / name).write_bytes(b"")
    monkeypatch.setattr(llvm, "_candidate_paths", lambda: [str(p) for p in tmp_path.iterdir()])
    assert llvm.find_libllvm() == str(tmp_path / "libLLVM.so.21.1")
    assert llvm.find_libllvm(min_version=22) is None


def test_configure_respects_the_users_choice(monkeypatch):
    monkeypatch.setenv(llvm.ENV_VAR, "/my/own/libLLVM.so")
    assert llvm.configure() == "/my/own/libLLVM.so"
    assert os.environ[llvm.ENV_VAR] == "/my/own/libLLVM.so"


def test_import_loads_a_working_libllvm():
    """In a fresh interpreter, `import mifaces` makes Dr.Jit load LLVM >= 16."""
    code = ("import mifaces, drjit as dr, mitsuba as mi\n"
            "x = dr.arange(mi.Float, 8)\n"
            "print(int(dr.sum(x)[0]) if dr.is_array_v(dr.sum(x)) else int(dr.sum(x)))\n"
            "from mifaces.runtime import llvm; print(llvm.loaded_libllvm())")
    env = {k: v for k, v in os.environ.items() if k != llvm.ENV_VAR}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=120)
    assert out.returncode == 0, out.stderr
    total, path = out.stdout.split()
    assert total == "28"
    assert llvm._major_version(path) >= llvm.MIN_VERSION


def test_importing_drjit_first_with_an_old_llvm_gives_a_clear_error(tmp_path):
    """Dr.Jit reads DRJIT_LIBLLVM_PATH at import: if it was imported first and
    took an LLVM older than 16, mifaces refuses with the fix in the message."""
    old = [p for p in ("/usr/lib/x86_64-linux-gnu/libLLVM-15.so.1", "/usr/lib/aarch64-linux-gnu/libLLVM-15.so.1")
           if os.path.exists(p)]
    if not old:
        pytest.skip("no LLVM 15 on this machine to provoke the situation")
    env = {**os.environ, llvm.ENV_VAR: old[0]}
    code = f"import os, drjit; os.environ.pop('{llvm.ENV_VAR}'); import mifaces"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=120)
    assert out.returncode != 0
    assert "Import mifaces before drjit" in out.stderr and "LLVM 15" in out.stderr


def test_missing_llvm_backend_names_what_to_install(monkeypatch):
    monkeypatch.setattr(dr, "has_backend", lambda backend: False)
    with pytest.raises(RuntimeError, match="karellen-llvm-core"):
        mifaces.set_variant("llvm_ad_rgb")


def test_set_variant_registers_plugins_and_rejects_unknown_names():
    with pytest.raises(ValueError, match="'llvm_rgb_fast'"):
        mifaces.set_variant("llvm_rgb_fast")
    for variant in ("scalar_rgb", "llvm_ad_rgb"):
        assert mifaces.set_variant(variant) == variant
        assert mi.variant() == variant
        mi.load_dict({"type": "ward"})


def test_default_variant(monkeypatch):
    monkeypatch.setenv("MIFACES_VARIANT", "scalar_rgb")
    assert mifaces.default_variant() == "scalar_rgb"
    monkeypatch.delenv("MIFACES_VARIANT")
    expected = "cuda_ad_rgb" if dr.has_backend(dr.JitBackend.CUDA) else "llvm_ad_rgb"
    assert mifaces.default_variant() == expected
