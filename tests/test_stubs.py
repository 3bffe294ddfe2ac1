"""The checked-in stubs of popup._core match the extension (mypy.stubtest)."""

import subprocess
import sys

import pytest


def test_stubtest():
    pytest.importorskip("mypy")
    r = subprocess.run([sys.executable, "-m", "mypy.stubtest", "popup._core"], capture_output=True, text=True)
    assert r.returncode == 0, r.stdout + r.stderr


def test_public_all():
    import popup

    for name in popup.__all__:
        assert hasattr(popup, name), name


def test_package_type_checks():
    pytest.importorskip("mypy")
    import pathlib

    pkg = pathlib.Path(__file__).resolve().parents[1] / "python" / "popup"
    r = subprocess.run([sys.executable, "-m", "mypy", str(pkg), "--ignore-missing-imports"], capture_output=True, text=True)
    assert r.returncode == 0, r.stdout + r.stderr
