"""The packages are layered: the core (`layerskin_exp`) < `hardware` < `protocols`, and `analysis`
on the core alone, beside `hardware`: the post-hoc analysis of session files never drives a rig,
and the protocols' studies (the design search, the sensitivity screen) run campaigns and measure
them with it. A layer imports only what is below it, and no modules import each other in a circle.

Two independent views, so neither a lazy import nor a string import slips through:
- the source: every import statement of every module (function-level ones included, since they
  run when the function does, and `TYPE_CHECKING` ones, since the module needs the type), read
  with `ast`;
- a live process per layer: import every module of the layer, register its schemas and load
  each of its commands' configs, then look at `sys.modules`.
"""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
PACKAGES = ("layerskin_exp", "hardware", "protocols", "analysis")
# What each package must never import.
FORBIDDEN = {
    "layerskin_exp": ("hardware", "protocols", "analysis"),
    "hardware": ("protocols", "analysis"),
    "protocols": (),
    "analysis": ("hardware", "protocols"),
}


def _modules(repo: Path) -> dict[str, tuple[Path, bool]]:
    """{dotted name: (file, is_package)} of every module of the four packages."""
    mods = {}
    for pkg in PACKAGES:
        for path in sorted((repo / pkg).rglob("*.py")):
            parts = list(path.relative_to(repo).with_suffix("").parts)
            is_pkg = parts[-1] == "__init__"
            mods[".".join(parts[:-1] if is_pkg else parts)] = (path, is_pkg)
    return mods


def import_graph(repo: Path) -> dict[str, set[str]]:
    """{module: modules of the four packages it imports}. `from pkg import name` is an edge to
    the submodule pkg.name where one exists, else to pkg; a module's own parent packages are not
    edges (importing any submodule runs them; that is no dependency). An import under
    `if TYPE_CHECKING:` is an edge like any other: a type a module needs is a dependency, and a
    circle closed by one is a circle all the same."""
    mods = _modules(repo)

    def resolve(name: str) -> str | None:
        while name and name not in mods:
            name = name.rpartition(".")[0]
        return name or None

    graph: dict[str, set[str]] = {}
    for name, (path, is_pkg) in mods.items():
        tree = ast.parse(path.read_text(), str(path))
        package = name if is_pkg else name.rpartition(".")[0]
        targets: list[str] = []
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                targets += [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    up = package.split(".")[: len(package.split(".")) - node.level + 1]
                    base = ".".join([*up, base] if base else up)
                targets += [f"{base}.{a.name}" if f"{base}.{a.name}" in mods else base for a in node.names]
        graph[name] = {r for t in targets if (r := resolve(t)) and r != name and not name.startswith(r + ".")}
    return graph


def upward_imports(graph: dict[str, set[str]]) -> list[str]:
    return sorted(f"{m} -> {t}" for m, ts in graph.items() for t in ts
                  if t.split(".")[0] in FORBIDDEN[m.split(".")[0]])


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components with more than one module (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []
    for root in sorted(graph):
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            v, children = work[-1]
            for w in children:
                if w not in index:
                    index[w] = low[w] = len(index)
                    stack.append(w)
                    on_stack.add(w)
                    work.append((w, iter(sorted(graph.get(w, ())))))
                    break
                if w in on_stack:
                    low[v] = min(low[v], index[w])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[v])
                if low[v] == index[v]:
                    comp = []
                    while True:
                        w = stack.pop()
                        on_stack.discard(w)
                        comp.append(w)
                        if w == v:
                            break
                    if len(comp) > 1:
                        found.append(sorted(comp))
    return found


def test_no_module_imports_a_layer_above_its_own():
    assert upward_imports(import_graph(REPO)) == []


def test_no_modules_import_each_other_in_a_circle():
    assert cycles(import_graph(REPO)) == []


def test_the_checks_see_an_upward_import_and_a_circle(tmp_path):
    """The two checks on a made-up tree that has both faults (one circle through a function-level
    import, one closed by a `TYPE_CHECKING` import), and on the same tree without them."""
    for pkg in PACKAGES:
        (tmp_path / pkg).mkdir()
        (tmp_path / pkg / "__init__.py").write_text("")
    (tmp_path / "layerskin_exp" / "a.py").write_text("def f():\n    from layerskin_exp import b\n")
    (tmp_path / "layerskin_exp" / "b.py").write_text("from layerskin_exp.a import f\n")
    (tmp_path / "layerskin_exp" / "c.py").write_text("def g():\n    import protocols.x\n")
    (tmp_path / "layerskin_exp" / "d.py").write_text("from layerskin_exp.e import T\n")
    (tmp_path / "layerskin_exp" / "e.py").write_text(
        "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from layerskin_exp.d import U\nT = int\n")
    (tmp_path / "protocols" / "x.py").write_text("from layerskin_exp import a, d\n")
    (tmp_path / "analysis" / "y.py").write_text("def h():\n    from protocols import x\n")  # a study in analysis
    graph = import_graph(tmp_path)
    assert upward_imports(graph) == ["analysis.y -> protocols.x", "layerskin_exp.c -> protocols.x"]
    assert cycles(graph) == [["layerskin_exp.a", "layerskin_exp.b"], ["layerskin_exp.d", "layerskin_exp.e"]]
    (tmp_path / "layerskin_exp" / "b.py").write_text("")
    (tmp_path / "layerskin_exp" / "c.py").write_text("")
    (tmp_path / "layerskin_exp" / "e.py").write_text("T = int\n")
    (tmp_path / "analysis" / "y.py").write_text("")
    graph = import_graph(tmp_path)
    assert upward_imports(graph) == [] and cycles(graph) == []


# What each layer's commands do to load their configs, run in a fresh interpreter after importing
# every module of the layer (its `__main__` modules excepted: they run a command when imported).
LOADS = {
    "layerskin_exp": (
        "from layerskin_exp.sim import physics_checks, preview, validate\n"
        "from layerskin_exp.config import compose\n"
        "compose('preview', ['sim.seed=1', 'out=x.png'])\n"
        "compose('validate', ['sim.seed=1'])\n"
    ),
    "hardware": (
        "from hardware import emulate\n"
        "emulate._compose('platform', ['sim.seed=1'])\n"
        "emulate._compose('gripper', [])\n"
    ),
    "protocols": (
        "from protocols import force_calibration, grip_depth\n"
        "from layerskin_exp.cli import preflight\n"
        "from layerskin_exp.config import compose\n"
        "compose('force_calibration', ['positions.count=2'])\n"
        "preflight('grip_depth', ['-m', 'grip_depth=6,9'])\n"
        "compose('sensitivity', ['size=quick', 'params=[sim.cover.friction]'])\n"
    ),
    "analysis": (
        "from analysis import cli, report\n"
        "from layerskin_exp.config import compose\n"
        "compose('report', ['analysis=demo'])\n"
        "compose('design_map', ['sweep_dir=data', 'n_jobs=2'])\n"
    ),
}


@pytest.mark.parametrize("layer", sorted(LOADS))
def test_loading_a_layer_and_its_configs_loads_nothing_above_it(layer):
    code = (
        "import importlib, pkgutil, sys\n"
        f"import {layer} as pkg\n"
        f"for m in pkgutil.walk_packages(pkg.__path__, '{layer}.'):\n"
        "    if not m.name.endswith('__main__'):\n"
        "        importlib.import_module(m.name)\n"
        + LOADS[layer]
        + f"above = {FORBIDDEN[layer]!r}\n"
        "print(','.join(sorted(k for k in sys.modules if k.split('.')[0] in above)))\n"
    )
    r = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, timeout=240)
    assert r.returncode == 0, r.stderr[-3000:]
    assert r.stdout.strip().splitlines()[-1:] in ([], [""]), f"{layer} loads {r.stdout.strip()}"
