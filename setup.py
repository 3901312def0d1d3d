"""Packages and data files of the one ``pibr`` distribution, found by walking its folders.

The repository's top-level folders are sub-packages of ``pibr`` (``server/`` installs as
``pibr.server``, ``cli/`` as ``pibr`` itself), a mapping setuptools' automatic discovery cannot
express; listing packages by hand once left ``pibr.client.methods`` out of every regular install.
So every folder with an ``__init__.py`` under a mapped folder is a package, and every other file
in it (outside ``__pycache__`` and hidden files) is package data. The metadata is in
pyproject.toml.
"""
import os

from setuptools import setup

# import name -> folder in the repository
PACKAGE_ROOTS = {
    "pibr": "cli",
    "pibr.protocol": "protocol",
    "pibr.common": "common",
    "pibr.scenes": "scenes",
    "pibr.server": "server",
    "pibr.client": "client",
    "pibr.bench": "bench",
}


def _is_package(folder: str) -> bool:
    return os.path.isfile(os.path.join(folder, "__init__.py"))


def _skipped(name: str) -> bool:
    return name.startswith(".") or name == "__pycache__" or name.endswith((".pyc", ".pyo"))


def discover(roots: dict[str, str]) -> tuple[list[str], dict[str, list[str]]]:
    """-> (package names, package data: package -> file patterns relative to its folder)."""
    packages, package_data = [], {}
    for root_name, root_folder in roots.items():
        for folder, dirs, files in os.walk(root_folder):
            dirs[:] = sorted(d for d in dirs if not _skipped(d))
            if not _is_package(folder):
                continue
            rel = os.path.relpath(folder, root_folder)
            name = root_name if rel == "." else root_name + "." + rel.replace(os.sep, ".")
            packages.append(name)
            data = [f for f in files if not f.endswith(".py") and not _skipped(f)]
            # Folders without __init__.py below a package are its data (traces, assets).
            for sub in dirs:
                for sub_folder, sub_dirs, sub_files in os.walk(os.path.join(folder, sub)):
                    if _is_package(sub_folder):
                        sub_dirs[:] = []
                        continue
                    sub_dirs[:] = [d for d in sub_dirs if not _skipped(d)]
                    data += [os.path.relpath(os.path.join(sub_folder, f), folder).replace(os.sep, "/")
                             for f in sub_files if not _skipped(f)]
            if data:
                package_data[name] = sorted(data)
    return packages, package_data


if __name__ == "__main__":
    PACKAGES, PACKAGE_DATA = discover(PACKAGE_ROOTS)
    setup(package_dir=PACKAGE_ROOTS, packages=PACKAGES, package_data=PACKAGE_DATA)
