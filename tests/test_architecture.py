"""The package's shape: imports run one way, no module too big to read, no hidden imports."""

from __future__ import annotations

import ast
import os
import subprocess
import sys
from pathlib import Path

from tests.conftest import REPO

PACKAGE = REPO / "vid2sim"
#: Largest module [lines]: above it a module holds more than one concern (issue 12).
MAX_MODULE_LINES = 600
#: Longest function [lines] before it should be named steps, and how many may still be
#: longer (the ones whose steps share too much state to split cleanly yet).
MAX_FUNCTION_LINES = 80
MAX_LONG_FUNCTIONS = 10
#: Where a vid2sim import inside a function is allowed, and why.
LAZY_IMPORTS_ALLOWED = {
    # The CLI imports each command's application module when the command runs, so that
    # `vid2sim --help` and light commands do not load onnxruntime, osmnx or highway-env.
    "vid2sim.cli.stage_commands", "vid2sim.cli.scenario_commands", "vid2sim.cli.batch_commands",
    # `import vid2sim` registers the gym environment; checked only where the env is wanted.
    "vid2sim.evaluate.replay",
    # highway-env (and pygame) only for the highway-env export's preview picture.
    "vid2sim.app.commands",
    # the whole pipeline is loaded by the first row a batch worker builds, so that a driver
    # resuming a finished manifest starts in a second.
    "vid2sim.app.batch.worker",
}
#: Packages the video-only commands (`vid2sim detect`, `vid2sim track`) must not load: the road,
#: export, evaluation and plotting stacks (0.1-0.5 s each to import, about 2 s together before
#: the first frame when the commands imported them, issue 15). pyproj is only needed once a GPS
#: fix is converted (vid2sim.core.enu loads it then).
NOT_FOR_VIDEO_COMMANDS = ("matplotlib", "highway_env", "pygame", "pandas", "networkx", "shapely",
                          "osmnx", "geopandas", "pyrosm", "scenariogeneration", "pyproj",
                          "sklearn", "ray", "pyarrow")
#: Submodules of allowed packages that are heavy to import (scipy.signal 1-3 s, optimize ~1 s here).
NOT_FOR_VIDEO_COMMANDS_SUBMODULES = ("scipy.signal", "scipy.stats", "scipy.optimize")
#: The layers, lowest first: a module may import its own layer and the layers below.
LAYERS = (
    ("base",),
    ("core",),
    STAGES := ("geo", "detect", "calib", "export"),
    # consumers of the stages: evaluation (replay, scoring, truth readers), policy testing
    # on the exported environment, generators of samples
    ("evaluate", "adas", "samples"),
    ("app",),
    ("cli", "__main__"),
)


def _modules() -> dict[str, Path]:
    mods = {}
    for path in PACKAGE.rglob("*.py"):
        parts = path.relative_to(REPO).with_suffix("").parts
        name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
        mods[name] = path
    return mods


MODULES = _modules()


def _imports(path: Path) -> list[tuple[str, bool]]:
    """(imported vid2sim module, inside a function) of every import in a file."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    inside: set[int] = set()
    for fn in ast.walk(tree):
        if isinstance(fn, ast.FunctionDef | ast.AsyncFunctionDef):
            inside.update(id(n) for n in ast.walk(fn) if n is not fn)
    out = []
    for node in ast.walk(tree):
        names: list[str] = []
        if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            # `from pkg import mod` imports the module; `from mod import name` the module
            subs = [f"{node.module}.{a.name}" for a in node.names]
            names = [s for s in subs if s in MODULES] or [node.module]
        elif isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        for name in names:
            if name == "vid2sim" or name.startswith("vid2sim."):
                out.append((name, id(node) in inside))
    return out


def _graph() -> dict[str, set[str]]:
    mods = _modules()
    return {m: {n for n, _ in _imports(p) if n in mods and n != m} for m, p in mods.items()}


def _layer(module: str) -> int:
    top = module.split(".")[1] if "." in module else ""
    for k, names in enumerate(LAYERS):
        if top in names:
            return k
    raise AssertionError(f"{module}: not in any layer of tests/test_architecture.py")


def test_no_module_is_too_long():
    long = {m: n for m, p in _modules().items()
            if (n := len(p.read_text(encoding="utf-8").splitlines())) > MAX_MODULE_LINES}
    assert not long, long


def test_long_functions_are_few():
    long = []
    for m, p in _modules().items():
        for node in ast.walk(ast.parse(p.read_text(encoding="utf-8"))):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                n = node.end_lineno - node.lineno + 1
                if n > MAX_FUNCTION_LINES:
                    long.append(f"{m}.{node.name} ({n} lines)")
    assert len(long) <= MAX_LONG_FUNCTIONS, sorted(long)


def test_no_import_cycle():
    graph = _graph()
    seen: dict[str, int] = {}  # 1 on the stack, 2 done

    def visit(m: str, stack: list[str]) -> None:
        seen[m] = 1
        for n in sorted(graph[m]):
            if n.startswith(m + ".") or m.startswith(n + "."):
                continue  # a package and its own modules
            assert seen.get(n) != 1, " -> ".join([*stack, m, n])
            if n not in seen:
                visit(n, [*stack, m])
        seen[m] = 2

    for m in sorted(graph):
        if m not in seen:
            visit(m, [])


def test_imports_run_down_the_layers():
    wrong = []
    for m, targets in _graph().items():
        if m == "vid2sim":
            continue
        for n in targets:
            if n != "vid2sim" and _layer(n) > _layer(m):
                wrong.append(f"{m} -> {n}")
    assert not wrong, wrong


def test_a_stage_never_imports_another_stage():
    """geo, detect and export receive records; none reaches into another (STYLE.md)."""
    crossing = []
    for m, targets in _graph().items():
        top = m.split(".")[1] if "." in m else ""
        for n in targets:
            other = n.split(".")[1] if "." in n else ""
            if top in STAGES and other in STAGES and other != top:
                crossing.append(f"{m} -> {n}")
    assert not crossing, crossing


def test_no_hidden_imports_of_vid2sim_modules():
    hidden = [(m, n) for m, p in _modules().items() if m not in LAZY_IMPORTS_ALLOWED
              for n, in_function in _imports(p) if in_function]
    assert not hidden, hidden


def test_no_test_imports_a_benchmark_and_no_benchmark_a_test():
    for folder, other in (("tests", "benchmarks"), ("benchmarks", "tests")):
        for path in (REPO / folder).rglob("*.py"):
            tree = ast.parse(path.read_text(encoding="utf-8"))
            for node in ast.walk(tree):
                mods = ([node.module or ""] if isinstance(node, ast.ImportFrom)
                        else [a.name for a in node.names] if isinstance(node, ast.Import)
                        else [])
                bad = [x for x in mods if x == other or x.startswith(other + ".")]
                assert not bad, f"{path.relative_to(REPO)} imports {bad}"


def test_the_video_commands_load_only_the_detection_stack():
    """What `vid2sim track` / `detect` import before the first frame (the CLI and their
    application module), in a fresh interpreter: none of the heavy stacks they do not use."""
    code = ("import sys, vid2sim.cli, vid2sim.app.tracking; "
            "print(' '.join(sorted(set(sys.modules))))")
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env,
                          cwd=REPO, timeout=300, check=False)
    assert proc.returncode == 0, proc.stderr[-2000:]
    modules = set(proc.stdout.split())
    loaded = {m.split(".")[0] for m in modules}
    assert {"vid2sim", "numpy", "cv2"} <= loaded, "the probe did not import the command"
    assert not loaded & set(NOT_FOR_VIDEO_COMMANDS), sorted(loaded & set(NOT_FOR_VIDEO_COMMANDS))
    heavy = modules & set(NOT_FOR_VIDEO_COMMANDS_SUBMODULES)
    assert not heavy, sorted(heavy)


#: Most modules directly in the package root: the entry points only; everything else lives in
#: a folder named for its concept.
MAX_ROOT_MODULES = 5
#: Most files directly in ``detect/``: the pipeline and the ties between the four wings.
MAX_DETECT_FILES = 8
#: The wings of ``detect/``: each a concern of its own that the pipeline ties together.
DETECT_WINGS = ("vehicles", "tracking", "lanes", "ranging")


def test_the_package_root_holds_only_entry_points():
    root = sorted(p.name for p in PACKAGE.glob("*.py"))
    assert len(root) <= MAX_ROOT_MODULES, root


def test_detect_is_a_pipeline_and_four_wings():
    flat = sorted(p.name for p in (PACKAGE / "detect").glob("*.py"))
    assert len(flat) <= MAX_DETECT_FILES, flat
    for wing in DETECT_WINGS:
        assert (PACKAGE / "detect" / wing / "__init__.py").exists(), wing


def test_the_detect_wings_import_nothing_of_detect_but_themselves():
    crossing = []
    for m, targets in _graph().items():
        parts = m.split(".")
        if parts[:2] != ["vid2sim", "detect"] or len(parts) < 3 or parts[2] not in DETECT_WINGS:
            continue
        for n in targets:
            other = n.split(".")
            # neither another wing nor the ties above them (pipeline, assign, schedule)
            if other[:2] == ["vid2sim", "detect"] and len(other) > 2 and other[2] != parts[2]:
                crossing.append(f"{m} -> {n}")
    assert not crossing, crossing


def test_no_file_name_is_used_twice():
    """One name, one concept: ``kalman.py`` in two packages makes a reader ask which one."""
    seen: dict[str, list[str]] = {}
    for path in PACKAGE.rglob("*.py"):
        if path.name != "__init__.py":
            seen.setdefault(path.name.lstrip("_"), []).append(str(path.relative_to(PACKAGE)))
    twice = {k: v for k, v in seen.items() if len(v) > 1}
    assert not twice, twice
