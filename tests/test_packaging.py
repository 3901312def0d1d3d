"""A regular (non-editable) install holds the whole project, and its processes start from anywhere.

An editable install once hid two faults that broke the README's first command for everyone:
a package left out of the hand-written package list, and child processes importing a local
``pibr/`` folder instead of the installed package. These tests build a real wheel and start
real processes from the repository's root.
"""
import os
import shutil
import subprocess
import sys
import time
import zipfile

import pytest

from pibr.bench.processes import PibrProcess, ProcessFailed

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SKIPPED_NAMES = ("__pycache__", ".pytest_cache")


def _mapped_folders() -> dict[str, str]:
    """Every top-level folder with an __init__.py except tests -> the import name it installs as
    (``cli/`` is the package root ``pibr``, every other folder ``pibr.<folder>``)."""
    folders = sorted(d for d in os.listdir(ROOT)
                     if d != "tests" and os.path.isfile(os.path.join(ROOT, d, "__init__.py")))
    return {d: "pibr" if d == "cli" else f"pibr.{d}" for d in folders}


def _expected_wheel_files() -> set[str]:
    """Paths inside the wheel of every module, package marker and data file under the mapped folders."""
    expected = set()
    for folder, name in _mapped_folders().items():
        base = os.path.join(ROOT, folder)
        for dirpath, dirs, files in os.walk(base):
            dirs[:] = [d for d in dirs if d not in SKIPPED_NAMES and not d.startswith(".")]
            rel = os.path.relpath(dirpath, base)
            prefix = name.replace(".", "/") + ("" if rel == "." else "/" + rel.replace(os.sep, "/"))
            expected |= {f"{prefix}/{f}" for f in files if not f.endswith(".pyc") and not f.startswith(".")}
    return expected


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> str:
    """A wheel built from a copy of the working tree, as ``pip install .`` builds one."""
    work = tmp_path_factory.mktemp("wheel")
    src = work / "src"
    shutil.copytree(ROOT, src, ignore=shutil.ignore_patterns(
        ".git", "out", "out-*", "build", "dist", "*.egg-info", "__pycache__", ".pytest_cache", ".hypothesis"))
    res = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(work / "dist"), str(src)],
                         capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stderr[-3000:]
    (path,) = (work / "dist").glob("pibr-*.whl")
    return str(path)


def test_top_level_folders_are_the_documented_packages():
    assert _mapped_folders() == {"bench": "pibr.bench", "cli": "pibr", "client": "pibr.client", "common": "pibr.common",
                                 "protocol": "pibr.protocol", "scenes": "pibr.scenes", "server": "pibr.server"}
    # No folder named like the package at the root: it would shadow the installed one for
    # every `python -m pibr` started there.
    assert not os.path.exists(os.path.join(ROOT, "pibr"))


def test_wheel_holds_every_package_and_data_file(wheel):
    names = set(zipfile.ZipFile(wheel).namelist())
    expected = _expected_wheel_files()
    packages = {p for p in expected if p.endswith("/__init__.py")}
    assert "pibr/client/methods/__init__.py" in packages and "pibr/protocol/edgecodec/__init__.py" in packages
    assert not expected - names, f"missing from the wheel: {sorted(expected - names)}"
    # The shipped data (built-in traces, the real asset) is in, and nothing of the build's own.
    assert "pibr/common/traces/data/pred6dof/1.csv" in names
    assert "pibr/scenes/data/assets/spot_triangulated.obj" in names
    assert not [n for n in names if "__pycache__" in n or n.endswith(".pyc") or n.startswith("tests/")]
    entry_points = next(n for n in names if n.endswith(".dist-info/entry_points.txt"))
    assert "pibr = pibr.cli:main" in zipfile.ZipFile(wheel).read(entry_points).decode()


def test_a_child_that_exits_before_announcing_its_port_is_reported_at_once(tmp_path):
    """Started from the repository's root, as a newcomer does; the child fails (unknown scene),
    and the parent says so with its exit code and output instead of waiting out the timeout."""
    cwd = os.getcwd()
    os.chdir(ROOT)
    try:
        proc = PibrProcess("server", ["serve", "--port", "0", "--scene", "no-such-scene"],
                           str(tmp_path / "server.log"))
        t0 = time.monotonic()
        with pytest.raises(ProcessFailed) as err:
            proc.wait_listening(timeout=300)
        waited = time.monotonic() - t0
        proc.stop()
    finally:
        os.chdir(cwd)
    message = str(err.value)
    assert "server exited with code 2 before it announced a port" in message
    assert "unknown scene 'no-such-scene'" in message
    assert "ModuleNotFoundError" not in message and "Traceback" not in message
    assert waited < 150, f"waited {waited:.0f} s for a process that had exited"
