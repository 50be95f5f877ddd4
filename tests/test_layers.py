"""The package's floors: every import, at module level or inside a
function, points down (DESIGN.md), so the numerics never depend on the
runners and a subpackage can be read without the ones above it."""

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parent.parent / "bearcat"

FLOORS = {
    "cli": 6,
    "studies": 5,
    "suites": 5,
    "figures": 5,
    "runtime": 4,
    "plugins": 4,
    "scenarios": 3,
    "agents": 2,
    "bus": 1,
    "netem": 1,
    "solvers": 1,
    "maps": 1,
    "validation": 0,
}
"""The floor of each subpackage, and of the two modules beside them: the
public face of the registries at the top (``plugins``) and the typed reading
of files at the bottom (``validation``), which the scenarios, the profiles
and the maps share. An import may reach only a lower floor."""

BESIDE = {("netem", "bus"), ("maps", "solvers")}
"""The arrows allowed between subpackages of one floor: netem reads the bus's
message types, maps rasterizes to the solvers' grid."""


def arrows() -> set[tuple[str, str, str]]:
    """Each (importing subpackage, imported subpackage, importing file)."""
    found = set()
    for path in PACKAGE.rglob("*.py"):
        parts = path.relative_to(PACKAGE).parts
        if parts[0] in ("__init__.py", "__main__.py"):
            continue  # they stand above every floor
        source = parts[0].removesuffix(".py")
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.ImportFrom) and node.module:
                names = [node.module]
            elif isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            else:
                continue
            for name in names:
                dotted = name.split(".")
                if dotted[0] == "bearcat" and len(dotted) > 1 and dotted[1] != source:
                    found.add((source, dotted[1], str(path.relative_to(PACKAGE))))
    return found


def test_every_subpackage_has_a_floor():
    folders = {p.name for p in PACKAGE.iterdir() if (p / "__init__.py").is_file()}
    modules = {p.stem for p in PACKAGE.glob("*.py")} - {"__init__", "__main__"}
    assert folders | modules == set(FLOORS)


def test_every_import_points_down():
    upward = sorted(
        f"{where} imports bearcat.{target}"
        for source, target, where in arrows()
        if FLOORS[target] >= FLOORS[source] and (source, target) not in BESIDE
    )
    assert upward == []


def test_the_floors_are_all_used():
    """The graph is as deep as the design draws it: a floor nothing imports
    from above would mean a subpackage drifted out of its place."""
    reached = {FLOORS[target] for _, target, _ in arrows()}
    assert reached == set(range(0, 6))


def test_no_command_module_imports_another():
    """What two commands share lives in the CLI's helpers (arguments, output,
    progress, writing, presolve), so each command reads on its own."""
    from bearcat.cli.main import COMMANDS

    modules = {module for names, _ in COMMANDS.values() for module in names}
    reaching = sorted(
        f"cli/{module}.py imports bearcat.cli.{name}"
        for module in modules
        for name in imported_from_cli(PACKAGE / "cli" / f"{module}.py")
        if name in modules
    )
    assert reaching == []


def imported_from_cli(path: Path) -> set[str]:
    """The modules of ``bearcat.cli`` that ``path`` imports, however it spells it."""
    names = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.ImportFrom) and node.module == "bearcat.cli":
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and (node.module or "").startswith("bearcat.cli."):
            names.add(node.module.split(".")[2])
        elif isinstance(node, ast.Import):
            names.update(a.name.split(".")[2] for a in node.names if a.name.startswith("bearcat.cli."))
    return names
