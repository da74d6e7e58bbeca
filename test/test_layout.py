"""The package's import structure: one direction of imports, no cycles, tools never installed.

Layers, lowest first: ``core`` (numpy/scipy/OpenCV only) <- ``synth`` and the I/O layer
(message conversion, bag I/O, synchronisation, scoring) <- the node and the evaluation <- the
``endeff`` CLI. Development tools (``tools/``) sit on top and are imported by nothing in the
package. Read statically (every import statement, also those inside functions), so a lazy
import cannot hide a cycle.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
PACKAGE = REPO / 'endeff_ros'


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(REPO).with_suffix('').parts)
    if parts[-1] == '__init__':
        parts.pop()
    return '.'.join(parts)


def _imports(path: Path, name: str) -> set[str]:
    """Modules of this repository that ``path`` (module ``name``) imports."""
    package = name if path.stem == '__init__' else name.rpartition('.')[0]
    found = set()
    for node in ast.walk(ast.parse(path.read_text(encoding='utf-8'))):
        if isinstance(node, ast.Import):
            found.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split('.')
                base = base[:len(base) - node.level + 1]
                mod = '.'.join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ''
            found.add(mod)
            found.update(f'{mod}.{a.name}' for a in node.names)
    return {m for m in found if m.split('.')[0] in ('endeff_ros', 'tools')}


def _graph() -> dict[str, set[str]]:
    paths = sorted(PACKAGE.rglob('*.py')) + sorted((REPO / 'tools').glob('*.py'))
    names = {_module_name(p): p for p in paths}
    graph = {}
    for name, path in names.items():
        deps = set()
        for mod in _imports(path, name):
            while mod and mod not in names:  # `from pkg import function` -> pkg
                mod = mod.rpartition('.')[0]
            if mod and mod != name:
                deps.add(mod)
        graph[name] = deps
    return graph


GRAPH = _graph()


def _layer(module: str) -> int:
    """0 core, 1 synth and I/O, 2 node and evaluation, 3 CLI, 4 tools."""
    if module.startswith('tools'):
        return 4
    if module in ('endeff_ros.cli',):
        return 3
    if module.startswith('endeff_ros.core') or module == 'endeff_ros':
        return 0
    if module in ('endeff_ros.ros.node', 'endeff_ros.ros.scheduler', 'endeff_ros.evaluate',
                  'endeff_ros.ros.processing', 'endeff_ros.ros.ros_params'):
        return 2
    return 1


def test_the_graph_is_read() -> None:
    assert 'endeff_ros.core.tracker' in GRAPH['endeff_ros.ros.node']
    assert 'endeff_ros.core.flow' in GRAPH['endeff_ros.core.tracker']


@pytest.mark.parametrize('module', sorted(GRAPH))
def test_imports_go_one_way(module: str) -> None:
    """No module imports one of a higher layer (core never imports I/O, I/O never the CLI)."""
    up = sorted(d for d in GRAPH[module] if _layer(d) > _layer(module)
                and not d.endswith('__init__') and d != 'endeff_ros')
    assert not up, f'{module} (layer {_layer(module)}) imports higher layers: {up}'


def test_no_import_cycles() -> None:
    """No cycle among modules, and none among subpackages (core/, synth/, bag/, ros/)."""
    def sub(m: str) -> str:
        parts = m.split('.')
        return '.'.join(parts[:2]) if parts[0] == 'endeff_ros' else parts[0]

    for graph in (GRAPH, {}):
        if not graph:  # the subpackage graph
            for m, deps in GRAPH.items():
                graph.setdefault(sub(m), set()).update(sub(d) for d in deps if sub(d) != sub(m))
        state: dict[str, int] = {}

        def visit(node: str, path: list[str], graph: dict[str, set[str]] = graph,
                  state: dict[str, int] = state) -> None:
            state[node] = 1
            for dep in sorted(graph.get(node, ())):
                if state.get(dep) == 1:
                    cycle = path[path.index(dep):] + [dep] if dep in path else [node, dep]
                    pytest.fail(f'import cycle: {" -> ".join(cycle)}')
                if dep not in state:
                    visit(dep, [*path, dep])
            state[node] = 2

        for node in sorted(graph):
            if node not in state:
                visit(node, [node])
