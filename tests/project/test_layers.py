"""The layers of the cosim package: each imports only the layers below it, so no import circle can form.

Every import counts: at module level, inside functions, and under ``if TYPE_CHECKING:`` (a circle hidden by
moving an import into a function is still a circle). The order is the one docs/architecture.md draws.
"""

from __future__ import annotations

import ast
import re
import shutil
from pathlib import Path

import pytest

from tests.helpers.paths import REPO

ENGINE = REPO / "src" / "cosim"

# Top to bottom; the packages of one row are siblings and may not import each other.
LAYERS: list[set[str]] = [
    {"cli"},
    {"studies"},
    {"analysis", "parallel"},
    {"results"},
    {"export"},
    {"execution"},
    {"system"},
    {"spec"},
    {"ssp"},
    {"master"},
    {"units"},
    {"fmus", "util"},
    {"errors"},
]
# Plug-ins shipped with cosim: they may use any layer, and no layer may import them (the engine knows no robot).
PLUGINS = {"models"}


def layer_of(package: str) -> int:
    for rank, row in enumerate(LAYERS):
        if package in row:
            return rank
    raise KeyError(package)


def imported_modules(path: Path, module: str) -> list[tuple[int, str]]:
    """(line, absolute module name) of every cosim import in the file, wherever it stands in the file."""
    is_package = path.name == "__init__.py"
    found = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            found += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = module.split(".")
                base = base[:len(base) - node.level + (1 if is_package else 0)]
                name = ".".join(base + ([node.module] if node.module else []))
            else:
                name = node.module or ""
            # `from cosim import x` may import the module cosim.x
            found += [(node.lineno, f"{name}.{a.name}") for a in node.names] if name == "cosim" else [(node.lineno, name)]
    return [(line, name) for line, name in found if name == "cosim" or name.startswith("cosim.")]


def upward_imports(engine: Path) -> list[str]:
    """Every import of ``engine`` (the src/cosim folder) that goes up, sideways between siblings, or into a
    plug-in package, as 'file:line: a -> b'."""
    problems = []
    for path in sorted(engine.rglob("*.py")):
        parts = path.relative_to(engine).with_suffix("").parts
        if len(parts) == 1 and parts[0] in ("__init__", "__main__"):
            continue  # the public face and `python -m cosim` sit above every layer
        source = parts[0].removesuffix(".py")
        if source in PLUGINS:
            continue
        module = ".".join(("cosim", *parts)).removesuffix(".__init__")
        for line, name in imported_modules(path, module):
            target = name.split(".")[1] if "." in name else ""
            if target == source or name == "cosim.__version__":  # the version is a constant of the root
                continue
            where = f"{path.relative_to(engine)}:{line}: {module} -> {name}"
            if not target or target in PLUGINS:
                problems.append(where)
            elif layer_of(target) <= layer_of(source):
                problems.append(where)
    return problems


def test_every_package_has_a_layer():
    packages = {p.name.removesuffix(".py") for p in ENGINE.iterdir()
                if (p.is_dir() and (p / "__init__.py").exists()) or (p.suffix == ".py")}
    packages -= {"__init__", "__main__"}
    placed = set().union(*LAYERS) | PLUGINS
    assert packages - placed == set(), "give these packages a row in LAYERS (and in docs/architecture.md)"


def test_each_layer_imports_only_the_layers_below_it():
    assert upward_imports(ENGINE) == []


def test_an_upward_import_hidden_in_a_function_is_found(tmp_path):
    """The check fails on a deliberately added upward import, even one inside a function."""
    copy = tmp_path / "cosim"
    shutil.copytree(ENGINE, copy, ignore=shutil.ignore_patterns("__pycache__", "*.so", "*.fmu"))
    victim = copy / "units" / "protocol.py"
    victim.write_text(victim.read_text(encoding="utf-8")
                      + "\n\ndef _sneaky():\n    from cosim.studies.sweep import Sweep\n    return Sweep\n",
                      encoding="utf-8")
    found = upward_imports(copy)
    assert len(found) == 1 and found[0].endswith("cosim.units.protocol -> cosim.studies.sweep"), found


@pytest.mark.parametrize("text", [
    "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from cosim.system.builder import System\n",
    "import cosim.cli.main\n",
    "from cosim import studies\n",
    "from ..models import trajectory\n",
])
def test_type_checking_blocks_module_imports_and_relative_imports_count_too(tmp_path, text):
    copy = tmp_path / "cosim"
    shutil.copytree(ENGINE, copy, ignore=shutil.ignore_patterns("__pycache__", "*.so", "*.fmu"))
    victim = copy / "master" / "algorithms.py"
    victim.write_text(victim.read_text(encoding="utf-8") + "\n" + text, encoding="utf-8")
    assert [p for p in upward_imports(copy) if p.startswith("master/algorithms.py")] != []


# -- inside a package: modules in no circle either (issue 34) ----------------------------------------------------


def module_graph(engine: Path) -> dict[str, set[str]]:
    """Module -> the modules of the same top-level package it imports (at module level, in functions, or under
    TYPE_CHECKING: every import counts, as between packages)."""
    modules = {".".join(("cosim", *p.relative_to(engine).with_suffix("").parts)).removesuffix(".__init__"): p
               for p in sorted(engine.rglob("*.py"))}
    graph: dict[str, set[str]] = {m: set() for m in modules}
    for module, path in modules.items():
        for _, name in imported_modules(path, module):
            while name and name not in modules:  # `from cosim.a.b import name`: the module cosim.a.b
                name = name.rpartition(".")[0]
            if name and name != module and name.split(".")[:2] == module.split(".")[:2]:
                graph[module].add(name)
    return graph


def module_circles(engine: Path) -> list[list[str]]:
    """Every set of modules of one package that import each other in a circle (strongly connected, > 1)."""
    graph, index, low, stack, on_stack, circles = module_graph(engine), {}, {}, [], set(), []

    def visit(v: str) -> None:  # Tarjan's algorithm
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                circles.append(sorted(component))

    for v in graph:
        if v not in index:
            visit(v)
    return circles


def long_functions(folder: Path, most: int = 60) -> list[str]:
    """'file:function (lines)' for every function of ``folder`` longer than ``most`` lines."""
    found = []
    for path in sorted(folder.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                lines = node.end_lineno - node.lineno + 1
                if lines > most:
                    found.append(f"{path.relative_to(folder.parent)}:{node.name} ({lines})")
    return found


def test_no_circle_among_the_modules_of_a_package():
    assert module_circles(ENGINE) == []


def test_a_circle_between_two_modules_of_a_package_is_found(tmp_path):
    copy = tmp_path / "cosim"
    shutil.copytree(ENGINE, copy, ignore=shutil.ignore_patterns("__pycache__", "*.so", "*.fmu"))
    victim = copy / "master" / "transfers.py"
    victim.write_text(victim.read_text(encoding="utf-8") + "\n\ndef _late():\n"
                      "    from cosim.master.algorithms import GaussSeidel\n    return GaussSeidel\n", encoding="utf-8")
    assert any("cosim.master.transfers" in circle for circle in module_circles(copy))


def test_the_stepping_core_has_no_function_over_60_lines():
    """master/ and execution/ stay readable: each function fits on a screen."""
    assert long_functions(ENGINE / "master") + long_functions(ENGINE / "execution") == []


# -- each package's face, and the picture of the layers in docs/architecture.md (generated from the code) --------

ARCHITECTURE = ENGINE.parent.parent / "docs" / "architecture.md"
PICTURE_BEGIN, PICTURE_END = "<!-- layers: generated by python -m tests.project.test_layers --write-docs -->", "<!-- /layers -->"


def offered_names(package: str) -> list[tuple[str, str]]:
    """(module, name) for each name the 'Offers:' paragraph of ``package``'s docstring gives as ``module.Name``
    (a bare ``Name`` is of the module named before it); the built-in models and kinds are named in words."""
    doc = ast.get_docstring(ast.parse((ENGINE / package / "__init__.py").read_text(encoding="utf-8"))) or ""
    paragraph = doc.partition("Offers:")[2].split("\n\n")[0]
    found, module = [], ""
    for text in re.findall(r"``([A-Za-z_][\w.]*)``", paragraph):
        if "." in text:
            module, _, name = text.rpartition(".")
        elif (ENGINE / package / f"{text}.py").exists() or (ENGINE / package / text).is_dir():
            found.append(("", text))  # a module or folder of the package named as such (models, unit kinds)
            continue
        else:
            name = text
        found.append((module, name))
    return found


def layer_picture() -> str:
    """The layers, top to bottom, each package with its modules and subfolders, as the tree has them."""
    lines = ["```"]
    for rank, row in enumerate(LAYERS, start=1):
        for package in sorted(row):
            folder = ENGINE / package
            if folder.is_dir():
                parts = sorted(p.stem for p in folder.glob("*.py") if p.stem != "__init__")
                parts += sorted(f"{p.name}/" for p in folder.iterdir() if (p / "__init__.py").exists())
            else:
                parts = [f"{package}.py"]
            text, label = ", ".join(parts), f"{rank:>2} {package + ('/' if folder.is_dir() else '')}"
            while text:
                cut = text if len(text) <= 96 else text[:text.rindex(", ", 0, 96) + 1]
                lines.append(f"{label:<14}{cut.strip()}")
                text, label = text[len(cut):].strip(), ""
    for package in sorted(PLUGINS):
        lines.append(f"{'  ' + package + '/':<14}a plug-in package: it may use any layer; no layer imports it")
    return "\n".join(lines + ["```"])


def test_every_package_says_what_it_offers_and_each_name_is_there():
    import importlib

    for package in sorted(set().union(*LAYERS) | PLUGINS):
        if not (ENGINE / package).is_dir():
            continue
        doc = ast.get_docstring(ast.parse((ENGINE / package / "__init__.py").read_text(encoding="utf-8"))) or ""
        assert "Offers:" in doc, f"cosim.{package}'s docstring says what it offers"
        for module, name in offered_names(package):
            if not module and ((ENGINE / package / f"{name}.py").exists() or (ENGINE / package / name).is_dir()):
                continue  # named as a module or folder: it is there
            target = importlib.import_module(f"cosim.{package}.{module}" if module else f"cosim.{package}")
            assert hasattr(target, name), f"cosim.{package}: {module}.{name} is offered but not there"


def test_the_picture_of_the_layers_in_the_docs_is_the_trees():
    text = ARCHITECTURE.read_text(encoding="utf-8")
    shown = text.split(PICTURE_BEGIN)[1].split(PICTURE_END)[0].strip()
    assert shown == layer_picture(), "run python -m tests.project.test_layers --write-docs"


if __name__ == "__main__":  # python -m tests.project.test_layers [--write-docs]: the numbers this check holds the tree to
    import sys

    if "--write-docs" in sys.argv:
        text = ARCHITECTURE.read_text(encoding="utf-8")
        before, rest = text.split(PICTURE_BEGIN)
        ARCHITECTURE.write_text(f"{before}{PICTURE_BEGIN}\n{layer_picture()}\n{PICTURE_END}{rest.split(PICTURE_END)[1]}",
                                encoding="utf-8")
    packages = sorted(set().union(*LAYERS) | PLUGINS)
    print(f"{len(packages)} top-level packages in {len(LAYERS)} layers (+ plug-ins {', '.join(sorted(PLUGINS))})")
    print(f"imports up, sideways or into a plug-in: {len(upward_imports(ENGINE))}")
    print(f"circles among the modules of a package: {len(module_circles(ENGINE))}")
    print(f"functions over 60 lines in master/ and execution/: "
          f"{len(long_functions(ENGINE / 'master') + long_functions(ENGINE / 'execution'))}")
