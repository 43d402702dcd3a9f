"""The layering of docs/architecture.md holds: imports go downwards, heavy packages stay in
their own layer, every exception is in the tree, and no module grows past 500 lines."""

import ast
import importlib
import inspect
import pkgutil
import subprocess
import sys
from pathlib import Path

import pytest

import snakekit
from snakekit import errors

PACKAGE = Path(snakekit.__file__).parent

LAYER = {
    "errors": 0, "model": 0, "host": 0, "handin": 1, "bridge": 1, "validate": 1, "progress": 1, "collision": 2, "kinematics": 2,
    "trajectory": 2, "profile_planner": 2,
    "run": 3, "robot": 3, "sim": 4, "hardware": 4, "emulator": 4, "plots": 5, "viewer": 5, "widgets": 5,
    "checks": 5, "start": 5, "notebook_check": 5, "watch": 1, "lesson_progress": 5, "cli": 6, "__init__": 6, "__main__": 6,
}
# Imports across one layer, on purpose (docs/architecture.md says why).
ALLOWED_SIDEWAYS = {("kinematics", "collision"), ("robot", "run"), ("emulator", "sim"), ("emulator", "hardware"), ("widgets", "plots"), ("lesson_progress", "notebook_check")}
# Third-party packages that only some parts of the kit may import.
HEAVY = {"pinocchio": {"kinematics", "collision"}, "coal": {"collision"}, "mujoco": {"sim"}, "meshcat": {"viewer"}, "zmq": {"viewer"},
         "ipywidgets": {"widgets"}, "dynamixel_sdk": {"hardware"},
         "matplotlib": {"plots", "widgets", "cli", "checks"}}


def sources():
    return sorted(p for p in PACKAGE.rglob("*.py"))


def part_of(path: Path) -> str:
    """The top-level part of the package a file belongs to (``hardware`` for hardware/bus.py)."""
    rel = path.relative_to(PACKAGE)
    return rel.parts[0] if len(rel.parts) > 1 else rel.stem


def imports(path: Path):
    """(internal part or None, top-level third-party name or None, line) for every import."""
    tree = ast.parse(path.read_text(), str(path))
    rel = path.relative_to(PACKAGE)
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for a in node.names:
                name = a.name.split(".")
                if name[0] == "snakekit":
                    yield (name[1] if len(name) > 1 else "__init__"), None, node.lineno
                else:
                    yield None, name[0], node.lineno
        elif isinstance(node, ast.ImportFrom):
            if node.level == 0:
                name = (node.module or "").split(".")
                if name[0] == "snakekit":
                    yield (name[1] if len(name) > 1 else "__init__"), None, node.lineno
                else:
                    yield None, name[0], node.lineno
                continue
            # relative: resolve against the file's package
            base = list(rel.parts[:-1])[: len(rel.parts) - node.level]
            target = base + (node.module.split(".") if node.module else [])
            if target:
                yield target[0], None, node.lineno
            else:  # "from .. import x": the names are modules of the package
                for a in node.names:
                    yield a.name, None, node.lineno


def test_every_part_has_a_layer():
    parts = {part_of(p) for p in sources()}
    assert parts <= set(LAYER), f"add {sorted(parts - set(LAYER))} to docs/architecture.md and LAYER"


@pytest.mark.parametrize("path", sources(), ids=lambda p: str(p.relative_to(PACKAGE)))
def test_imports_go_downwards(path):
    me = part_of(path)
    bad = []
    for internal, external, line in imports(path):
        if internal is not None and internal in LAYER and internal != me:
            if LAYER[internal] >= LAYER[me] and (me, internal) not in ALLOWED_SIDEWAYS:
                bad.append(f"line {line}: {me} (layer {LAYER[me]}) imports {internal} (layer {LAYER[internal]})")
        if external in HEAVY and me not in HEAVY[external]:
            bad.append(f"line {line}: {me} imports {external}, which belongs to {sorted(HEAVY[external])}")
    assert bad == [], "\n".join(bad)


def test_the_layer_rules_catch_an_upward_import(tmp_path, monkeypatch):
    """The checker itself: a kinematics module that imports the viewer is refused."""
    fake = PACKAGE / "kinematics.py"
    monkeypatch.setattr(Path, "read_text", lambda self, *a, **k: "from .viewer import Viewer\nimport meshcat\n")
    with pytest.raises(AssertionError, match="kinematics \\(layer 2\\) imports viewer \\(layer 5\\)"):
        test_imports_go_downwards(fake)


@pytest.mark.parametrize("module, heavy", [
    ("snakekit.trajectory", ("pinocchio", "mujoco", "meshcat", "matplotlib")),
    ("snakekit.model", ("pinocchio", "mujoco", "meshcat", "matplotlib")),
    ("snakekit.robot", ("pinocchio", "mujoco", "meshcat", "matplotlib")),
    ("snakekit.widgets", ("meshcat", "mujoco")),
])
def test_light_modules_load_without_the_heavy_ones(module, heavy):
    code = f"import sys, {module}; print(','.join(m for m in {heavy!r} if m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.strip()
    assert out == "", f"importing {module} loaded {out}"


def all_modules():
    names = ["snakekit"]
    for info in pkgutil.walk_packages([str(PACKAGE)], "snakekit."):
        names.append(info.name)
    return names


def test_every_exception_class_is_in_the_tree():
    outside, loose = [], []
    for name in all_modules():
        module = importlib.import_module(name)
        for obj_name, obj in vars(module).items():
            if inspect.isclass(obj) and issubclass(obj, BaseException) and obj.__module__ == name:
                if name != "snakekit.errors":
                    outside.append(f"{name}.{obj_name}")
                elif not issubclass(obj, errors.SnakekitError):
                    loose.append(obj_name)
    assert outside == [], f"exceptions defined outside snakekit/errors.py: {outside}"
    assert loose == [], f"exceptions not deriving from SnakekitError: {loose}"


def test_every_exception_is_exported():
    defined = {n for n, c in vars(errors).items() if inspect.isclass(c) and issubclass(c, BaseException)
               and c.__module__ == "snakekit.errors"}
    assert defined <= set(snakekit.__all__), sorted(defined - set(snakekit.__all__))
    for name in defined:
        assert getattr(snakekit, name) is getattr(errors, name)


BUILTIN_RAISES = {"ValueError", "TypeError", "RuntimeError", "KeyError", "IndexError", "OSError",
                  "Exception", "ImportError", "ZeroDivisionError", "AssertionError"}


@pytest.mark.parametrize("path", sources(), ids=lambda p: str(p.relative_to(PACKAGE)))
def test_no_builtin_exception_is_raised(path):
    bad = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Raise) and node.exc is not None:
            call = node.exc.func if isinstance(node.exc, ast.Call) else node.exc
            if isinstance(call, ast.Name) and call.id in BUILTIN_RAISES:
                bad.append(f"line {node.lineno}: raise {call.id}")
    assert bad == [], "raise a snakekit.errors class instead: " + "; ".join(bad)


@pytest.mark.parametrize("path", sources(), ids=lambda p: str(p.relative_to(PACKAGE)))
def test_no_module_is_over_500_lines(path):
    assert len(path.read_text().splitlines()) <= 500


# --- the grader: a package beside the kit, reached through an entry point ------------------------

GRADER = PACKAGE.parent / "grader"


def _grader_imports(path: Path) -> set[str]:
    """The grader modules ``path`` imports, at the top or inside a function."""
    out = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.level == 1:
            out |= {node.module.split(".")[0]} if node.module else {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom) and (node.module or "").startswith("grader."):
            out.add(node.module.split(".")[1])
        elif isinstance(node, ast.Import):
            out |= {a.name.split(".")[1] for a in node.names if a.name.startswith("grader.")}
    return out


@pytest.mark.parametrize("path", sources(), ids=lambda p: str(p.relative_to(PACKAGE)))
def test_the_kit_never_imports_the_grader(path):
    for node in ast.walk(ast.parse(path.read_text())):
        names = [a.name for a in node.names] if isinstance(node, ast.Import) else \
            [node.module or ""] if isinstance(node, ast.ImportFrom) and node.level == 0 else []
        assert not [n for n in names if n.split(".")[0] == "grader"], f"line {node.lineno}"


def test_snakekit_grade_reaches_the_grader_through_its_entry_point():
    from snakekit import cli

    import grader.cli
    import grader.collect
    import grader.lms

    assert cli.plugin_command("grade") is grader.cli.main
    assert cli.plugin_command("collect") is grader.collect.main
    assert (cli.plugin_command("return"), cli.plugin_command("export")) == (grader.lms.return_main, grader.lms.export_main)
    import grader.lab.cli

    assert cli.plugin_command("lab") is grader.lab.cli.main
    r = subprocess.run([sys.executable, "-m", "snakekit.cli", "grade", "--help"], capture_output=True, text=True,
                       timeout=120)
    assert r.returncode == 0 and "usage: snakekit grade" in r.stdout


def test_the_grader_has_no_import_cycle():
    graph = {p.stem: _grader_imports(p) & {q.stem for q in GRADER.glob("*.py")} for p in GRADER.glob("*.py")}
    done, on_path = set(), []

    def visit(m):
        if m in on_path:
            raise AssertionError("import cycle: " + " -> ".join(on_path[on_path.index(m):] + [m]))
        if m in done:
            return
        on_path.append(m)
        for n in sorted(graph.get(m, ())):
            visit(n)
        on_path.pop()
        done.add(m)

    for m in sorted(graph):
        visit(m)
    assert {"references", "score"} <= set(graph) and "references" not in graph["score"]


@pytest.mark.parametrize("path", sorted(GRADER.glob("*.py")), ids=lambda p: p.name)
def test_no_grader_module_is_over_600_lines(path):
    assert len(path.read_text().splitlines()) <= 600
