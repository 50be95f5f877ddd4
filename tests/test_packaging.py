"""The distribution installs one top-level name, ``bearcat``, with its data,
laid out as plain folders so that Python, pip and every static tool (an
editor's go-to-definition, a type checker) find the same code.

Names such as ``maps``, ``agents`` and ``scenarios`` belong to other
distributions on the package index; a wheel that installed them would be
overwritten by (or overwrite) those.
"""

import shutil
import subprocess
import sys
import sysconfig
import tomllib
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PACKAGE = ROOT / "bearcat"
DATA = (("*.geojson", "maps/data"), ("*.toml", "scenarios/data"), ("profiles.toml", "netem"))
QUERY = "from bearcat.solvers.ctf.sets import solve_ctf"


def copy_of_the_sources(into: Path) -> Path:
    """The checkout's files, so that a build or an editable install leaves nothing in the checkout."""
    source = into / "bearcat-source"
    shutil.copytree(
        ROOT, source, ignore=shutil.ignore_patterns(".git", ".venv", "build", "*.egg-info", "__pycache__", "runs")
    )
    return source


def pip(python: Path | str, *args: str) -> None:
    subprocess.run([str(python), "-m", "pip", "-q", *args], check=True, capture_output=True, timeout=300)


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    source = copy_of_the_sources(tmp_path_factory.mktemp("source"))
    out = tmp_path_factory.mktemp("wheel")
    pip(sys.executable, "wheel", "--no-deps", "-w", str(out), str(source))
    (path,) = out.glob("bearcat-*.whl")
    return path


def test_the_wheel_holds_only_bearcat_and_its_metadata(wheel):
    names = zipfile.ZipFile(wheel).namelist()
    top = {name.split("/")[0] for name in names}
    assert {t for t in top if not t.endswith(".dist-info")} == {"bearcat"}
    entry_points = next(n for n in names if n.endswith(".dist-info/entry_points.txt"))
    assert "bearcat = bearcat.cli.main:main" in zipfile.ZipFile(wheel).read(entry_points).decode()


def test_every_package_folder_and_data_file_is_in_the_wheel(wheel):
    names = set(zipfile.ZipFile(wheel).namelist())
    for init in PACKAGE.rglob("__init__.py"):
        relative = init.relative_to(ROOT).as_posix()
        assert relative in names, f"{relative} is not in the wheel"
    for pattern, folder in DATA:
        files = sorted((PACKAGE / folder).glob(pattern))
        assert files
        for f in files:
            assert f"bearcat/{folder}/{f.name}" in names


def test_no_import_machinery_of_our_own():
    """A path entry is all Python needs: nothing in ``sys.meta_path`` and no
    ``package-dir`` mapping of subpackages to other folders."""
    code = "import sys; n = len(sys.meta_path); import bearcat, bearcat.solvers.grid; print(len(sys.meta_path) - n)"
    run = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert run.stdout.strip() == "0", run.stderr
    setuptools = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    assert setuptools.get("package-dir", {}) == {"": "."}  # the root itself: packages are its plain folders


class Venv:
    """A virtual environment that holds only what a test installs into it,
    and reads every other package from this test's environment, behind its own."""

    def __init__(self, where: Path) -> None:
        subprocess.run([sys.executable, "-m", "venv", str(where)], check=True, capture_output=True, timeout=120)
        self.python = where / "bin" / "python"
        run = subprocess.run(
            [str(self.python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
            capture_output=True,
            text=True,
            check=True,
        )
        self.site = Path(run.stdout.strip())
        # A plain path line: the outer site's own .pth files (this checkout's editable install) are not read.
        (self.site / "zz-outer-site.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")

    def where(self, module: str, cwd: Path) -> Path:
        """The file ``module`` is imported from by a Python started in ``cwd``."""
        code = f"import {module} as m; print(m.__file__)"
        run = subprocess.run([str(self.python), "-c", code], cwd=cwd, capture_output=True, text=True, timeout=120)
        assert run.returncode == 0, run.stderr
        return Path(run.stdout.strip())


def definition(code: str, script: Path, project: Path, environment: Path | None = None) -> Path:
    """Where ``jedi`` (the engine behind many editors' go-to-definition) finds the last name of ``code``."""
    jedi = pytest.importorskip("jedi")
    env = None if environment is None else jedi.create_environment(str(environment), safe=False)
    found = jedi.Script(code, path=str(script), project=jedi.Project(str(project)), environment=env).goto(
        1, len(code), follow_imports=True
    )
    assert found, f"jedi finds no definition for {code!r}"
    return Path(found[0].module_path)


def test_an_editor_finds_the_solvers_from_a_checkout():
    assert definition(QUERY, ROOT / "scratch.py", ROOT) == PACKAGE / "solvers" / "ctf" / "sets.py"


def test_installs_of_either_kind_in_either_order_import_from_anywhere(tmp_path):
    """``pip install .``, then ``pip install -e .``, then ``pip install .``
    again, as a user trying both would; between them the numba cache that a
    run writes beside the installed solvers (``cache=True``), which pip's
    uninstall leaves behind. After each, ``bearcat.solvers.ctf.sets`` imports from
    the install just made, and an editor finds it there too."""
    source = copy_of_the_sources(tmp_path)
    venv = Venv(tmp_path / "venv")
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    installed = venv.site / "bearcat" / "solvers" / "ctf" / "sets.py"

    pip(venv.python, "install", "--no-deps", str(source))
    assert venv.where("bearcat.solvers.ctf.sets", elsewhere) == installed
    numba_cache = installed.parent / "__pycache__" / "ctf.solve-1.py311.nbi"
    numba_cache.parent.mkdir(exist_ok=True)
    numba_cache.write_bytes(b"index")

    pip(venv.python, "install", "--no-deps", "-e", str(source))
    assert numba_cache.exists()  # what made the checkout's package a namespace package before
    assert venv.where("bearcat.solvers.ctf.sets", elsewhere) == source / "bearcat" / "solvers" / "ctf" / "sets.py"
    assert venv.where("bearcat", elsewhere) == source / "bearcat" / "__init__.py"
    script = elsewhere / "scratch.py"
    assert definition(QUERY, script, elsewhere, venv.python) == source / "bearcat" / "solvers" / "ctf" / "sets.py"

    pip(venv.python, "install", "--no-deps", str(source))
    assert venv.where("bearcat.solvers.ctf.sets", elsewhere) == installed
    assert definition(QUERY, script, elsewhere, venv.python) == installed


def test_an_installed_wheel_run_from_a_checkout_imports_the_checkout(wheel, tmp_path):
    """A non-editable install run from the repository root: the checkout's
    ``bearcat/`` folder shadows the installed one whole, so the two never mix."""
    venv = Venv(tmp_path / "venv")
    pip(venv.python, "install", "--no-deps", str(wheel))
    assert venv.where("bearcat.bus.keys", tmp_path) == venv.site / "bearcat" / "bus" / "keys.py"
    assert venv.where("bearcat.bus.keys", ROOT) == PACKAGE / "bus" / "keys.py"
