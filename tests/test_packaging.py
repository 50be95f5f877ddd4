"""The distribution installs one top-level name, ``bearcat``, with its data.

Names such as ``maps``, ``agents`` and ``scenarios`` belong to other
distributions on the package index; a wheel that installed them would be
overwritten by (or overwrite) those.
"""

import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
FOLDERS = ("agents", "bus", "maps", "netem", "scenarios", "solvers")


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    """The wheel built from a copy of the sources, so the build leaves nothing in the checkout."""
    source = tmp_path_factory.mktemp("source") / "bearcat"
    shutil.copytree(
        ROOT, source, ignore=shutil.ignore_patterns(".git", ".venv", "build", "*.egg-info", "__pycache__", "runs")
    )
    out = tmp_path_factory.mktemp("wheel")
    subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(out), str(source)],
        check=True,
        capture_output=True,
        timeout=300,
    )
    (path,) = out.glob("bearcat-*.whl")
    return path


def test_the_wheel_holds_only_bearcat_and_its_metadata(wheel):
    names = zipfile.ZipFile(wheel).namelist()
    top = {name.split("/")[0] for name in names}
    assert {t for t in top if not t.endswith(".dist-info")} == {"bearcat"}
    entry_points = next(n for n in names if n.endswith(".dist-info/entry_points.txt"))
    assert "bearcat = bearcat.cli:main" in zipfile.ZipFile(wheel).read(entry_points).decode()


def test_every_package_folder_and_data_file_is_in_the_wheel(wheel):
    names = set(zipfile.ZipFile(wheel).namelist())
    for folder in FOLDERS + ("bearcat",):
        for init in (ROOT / folder).rglob("__init__.py"):
            relative = init.relative_to(ROOT).as_posix()
            installed = relative if folder == "bearcat" else f"bearcat/{relative}"
            assert installed in names, f"{relative} is not in the wheel"
    for pattern, folder in (("*.geojson", "maps/data"), ("*.toml", "scenarios/data"), ("profiles.toml", "netem")):
        files = sorted((ROOT / folder).glob(pattern))
        assert files
        for f in files:
            assert f"bearcat/{folder}/{f.name}" in names


def imported_from(cwd: Path, site: Path) -> dict[str, str]:
    """Where ``bearcat`` and ``bearcat.bus`` come from for a Python started in ``cwd``."""
    code = "import bearcat, bearcat.bus.keys as k; print(bearcat.__file__); print(k.__file__)"
    run = subprocess.run(
        [sys.executable, "-c", code], cwd=cwd, env={"PYTHONPATH": str(site)}, capture_output=True, text=True, timeout=60
    )
    assert run.returncode == 0, run.stderr
    package, module = run.stdout.split()
    return {"bearcat": package, "bearcat.bus": module}


def test_an_installed_wheel_imports_from_a_checkout_and_from_elsewhere(wheel, tmp_path):
    """A non-editable install run from the repository root: the checkout's
    ``bearcat/`` folder shadows the installed one, and its subpackages must
    still import (from the same checkout, so the two never mix)."""
    site = tmp_path / "site"
    subprocess.run(
        [sys.executable, "-m", "pip", "install", "--no-deps", "-q", "--target", str(site), str(wheel)],
        check=True,
        capture_output=True,
        timeout=300,
    )
    elsewhere = imported_from(tmp_path, site)
    assert all(path.startswith(str(site)) for path in elsewhere.values()), elsewhere
    in_checkout = imported_from(ROOT, site)
    assert in_checkout["bearcat"] == str(ROOT / "bearcat" / "__init__.py")
    assert in_checkout["bearcat.bus"] == str(ROOT / "bus" / "keys.py")
