"""The house rules of DESIGN.md's Layout, read from the source: imports point one way, no module
imports another in a circle, protocol/ holds only the contract, and the choices written in one
place stay there."""
import ast
import os
import re

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
#: folder -> import name (setup.py PACKAGE_ROOTS)
PACKAGES = {"cli": "pibr", "protocol": "pibr.protocol", "common": "pibr.common", "scenes": "pibr.scenes",
            "server": "pibr.server", "client": "pibr.client", "bench": "pibr.bench"}
#: what each package may import of pibr (besides itself); cli (pibr.*) may import everything
ALLOWED = {"protocol": set(), "common": {"protocol"}, "scenes": {"protocol", "common"},
           "server": {"protocol", "common", "scenes"}, "client": {"protocol", "common"},
           "bench": {"protocol", "common", "scenes", "server", "client"}}


def _modules() -> dict:
    """module name -> source path, for every module of the distribution."""
    out = {}
    for folder, name in PACKAGES.items():
        base = os.path.join(ROOT, folder)
        for dirpath, _, files in os.walk(base):
            for f in files:
                if f.endswith(".py"):
                    rel = os.path.relpath(os.path.join(dirpath, f), base)[:-3].replace(os.sep, ".")
                    rel = rel[:-len(".__init__")] if rel.endswith(".__init__") else rel
                    out[name if rel == "__init__" else f"{name}.{rel}"] = os.path.join(dirpath, f)
    return out


MODULES = _modules()


def _imports(module: str, path: str) -> set:
    """The modules of pibr that ``module`` imports anywhere in its source (deferred imports too)."""
    tree = ast.parse(open(path, encoding="utf-8").read())
    is_package = path.endswith("__init__.py")
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = module.split(".") if is_package else module.split(".")[:-1]
                base = base[:len(base) - (node.level - 1)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module
            subs = [f"{target}.{a.name}" for a in node.names if f"{target}.{a.name}" in MODULES]
            if len(subs) < len(node.names):
                found.add(target)
            found.update(subs)
    return {m for m in found if m in MODULES and m != module}


GRAPH = {m: _imports(m, p) for m, p in MODULES.items()}


def _package(module: str) -> str:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 and parts[1] in ALLOWED else "cli"


def test_imports_point_one_way():
    wrong = sorted(f"{m} imports {d}" for m, deps in GRAPH.items() for d in deps
                   if _package(m) != "cli" and _package(d) != _package(m)
                   and _package(d) not in ALLOWED[_package(m)])
    assert wrong == []


def test_no_module_imports_another_in_a_circle():
    """Tarjan's strongly connected components over every import, deferred ones included."""
    index, low, stack, on_stack, circles = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in GRAPH[v]:
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

    for v in GRAPH:
        if v not in index:
            visit(v)
    assert circles == []


def test_the_checker_sees_a_circle_and_a_wrong_direction(monkeypatch):
    """The two tests above can fail: a made-up circle and upward import are found."""
    monkeypatch.setitem(GRAPH, "pibr.protocol.pose", GRAPH["pibr.protocol.pose"] | {"pibr.protocol.trace"})
    with pytest.raises(AssertionError):
        test_no_module_imports_another_in_a_circle()
    monkeypatch.setitem(GRAPH, "pibr.client.app", GRAPH["pibr.client.app"] | {"pibr.server.renderer"})
    with pytest.raises(AssertionError):
        test_imports_point_one_way()


def test_protocol_holds_no_gl_traces_files_or_link_model():
    names = {m.split(".")[2] for m in MODULES if m.startswith("pibr.protocol.")}
    assert not names & {"gl", "link", "address", "trace_import", "trace_synth", "data"}
    source = open(MODULES["pibr.protocol.trace"], encoding="utf-8").read()
    assert "def load_trace" not in source and "def read_canonical_csv" not in source


def test_depth_codec_names_are_written_in_one_place():
    """Outside the registry (protocol/depth_codecs.py) and the plan that chooses between the two
    codecs for a bandwidth, no code compares a depth codec's name as a string or types the list."""
    compare = re.compile(r"""(==|!=)\s*["'](h264|edge)["']|["'](h264|edge)["']\s*(==|!=)""")
    listed = re.compile(r"""\(\s*["'](auto["'],\s*["'])?h264["'],\s*["']edge["']\s*\)""")
    offenders = []
    for module, path in MODULES.items():
        if module == "pibr.protocol.depth_codecs":
            continue
        for n, line in enumerate(open(path, encoding="utf-8"), 1):
            if compare.search(line) or listed.search(line):
                offenders.append(f"{module}:{n}: {line.strip()}")
    assert offenders == []


def test_no_module_builds_the_session_pipeline_by_hand():
    """The frame producer and the H.264 encoder are made only by the session pipeline."""
    built = re.compile(r"\b(FrameProducer|H264Encoder)\(")
    makers = sorted(m for m, p in MODULES.items() if built.search(open(p, encoding="utf-8").read()))
    assert makers == ["pibr.server.pipeline"]


def test_the_bench_command_line_and_the_simulation_agree_on_the_view_size():
    from pibr.bench.cli import BENCH_VIEW_SIZE as declared
    from pibr.bench.simulation import BENCH_VIEW_SIZE

    assert declared == BENCH_VIEW_SIZE
