"""The layering of docs/architecture.md holds: imports go downwards, heavy packages stay in
their own layer, every exception is in the tree, and no module grows past 500 lines."""

import ast
import builtins
import importlib
import inspect
import pkgutil
import re
import subprocess
import sys
from pathlib import Path

import pytest

import snakekit
from snakekit import errors

PACKAGE = Path(snakekit.__file__).parent

LAYER = {
    "errors": 0, "model": 0, "host": 0, "kernel_client": 0, "handin": 1, "bridge": 1, "validate": 1, "progress": 1, "collision": 2, "kinematics": 2,
    "trajectory": 2, "profile_planner": 2,
    "run": 3, "bags": 3, "robot": 3, "sim": 4, "hardware": 4, "emulator": 4, "plots": 5, "ros": 5, "viewer": 5, "widgets": 5,
    "checks": 5, "start": 5, "notebook_check": 5, "watch": 1, "cells": 1, "mistakes": 1, "closeness": 1, "verdicts": 1, "lesson_progress": 5, "cli": 6, "__init__": 6, "__main__": 6,
}
# Imports across one layer, on purpose (docs/architecture.md says why): at the module's top, and inside a function
# (they cost nothing until used)
SIDEWAYS_AT_IMPORT = {("lesson_progress", "notebook_check"), ("kinematics", "collision"), ("robot", "run"),
                      ("widgets", "plots")}
SIDEWAYS_INSIDE = {("run", "bags"), ("emulator", "sim"), ("emulator", "hardware")}
ALLOWED_SIDEWAYS = SIDEWAYS_AT_IMPORT | SIDEWAYS_INSIDE
# Third-party packages that only some parts of the kit may import.
HEAVY = {"pinocchio": {"kinematics", "collision"}, "coal": {"collision"}, "mujoco": {"sim"}, "meshcat": {"viewer"}, "zmq": {"viewer"},
         "ipywidgets": {"widgets"}, "dynamixel_sdk": {"hardware"}, "rosbags": {"bags"}, "mcap": {"bags"},
         "rospy": {"ros"}, "rosgraph": {"ros"}, "sensor_msgs": {"ros"}, "trajectory_msgs": {"ros"},
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


def _inside_functions(tree: ast.AST) -> set[int]:
    """The ids of the import statements of ``tree`` that are inside a function."""
    return {id(n) for f in ast.walk(tree) if isinstance(f, (ast.FunctionDef, ast.AsyncFunctionDef))
            for n in ast.walk(f) if isinstance(n, (ast.Import, ast.ImportFrom))}


def test_every_markdown_file_the_repository_names_exists():
    """A page, a comment or a message that sends a reader to a Markdown file sends them to one that is there
    (beside the file that names it, at the repository's top, or in docs/)."""
    root = PACKAGE.parent
    tracked = subprocess.run(["git", "ls-files"], cwd=root, capture_output=True, text=True).stdout.split()
    if not tracked:
        pytest.fail("git ls-files listed nothing: run the suite from a clone of the repository")
    missing = []
    for name in tracked:
        path = root / name
        if path.suffix not in (".py", ".md", ".sh", ".toml", ".txt", ".yaml", ".yml", ".ipynb") or name == "tests/durations.txt" \
                or not path.is_file():
            continue
        for ref in set(re.findall(r"(?<![\w/.:-])((?:\.{1,2}/|[\w-]+/)*[\w-]+\.md)\b", path.read_text(errors="replace"))):
            if not any((base / ref).exists() for base in (path.parent, root, root / "docs")):
                missing.append(f"{name}: {ref}")
    assert missing == [], missing


@pytest.mark.parametrize("package", sorted(p.name for p in PACKAGE.iterdir() if (p / "__init__.py").is_file()))
def test_every_module_of_a_kit_package_is_named_in_its_row_of_the_map(package):
    rows = [line for line in GRADER_MAP.read_text().splitlines() if line.startswith("| ")
            and line.split("|")[1].strip().isdigit() and line.split("|")[2].strip() in (f"`{package}/`", f"`{package}`")]
    assert len(rows) == 1, f"docs/architecture.md has no row for {package}/"
    missing = [p.stem for p in sorted((PACKAGE / package).glob("*.py")) if p.stem != "__init__"
               and f"`{p.stem}`" not in rows[0] and f"`{package}.{p.stem}`" not in rows[0]]
    assert missing == [], f"the row of {package}/ in docs/architecture.md does not name {missing}"


def test_the_sideways_imports_are_the_ones_the_map_lists_and_the_last_are_inside_a_function():
    text = GRADER_MAP.read_text()
    listed = re.findall(r"^- `(\w+)` -> `(\w+)`", text, re.M)
    assert set(listed) == ALLOWED_SIDEWAYS and len(listed) == len(ALLOWED_SIDEWAYS), listed
    inside = len(SIDEWAYS_INSIDE)
    words = {3: "three", 4: "four", 2: "two"}
    assert f"the last {words[inside]} are done inside a function" in " ".join(text.split())
    assert set(listed[-inside:]) == SIDEWAYS_INSIDE, listed
    at_top = []
    for path in sources():
        said_inside = {line: internal for internal, _, line in imports(path) if (part_of(path), internal) in SIDEWAYS_INSIDE}
        if not said_inside:
            continue
        tree = ast.parse(path.read_text())
        inner = _inside_functions(tree)
        at_top += [f"{path.relative_to(PACKAGE)} line {node.lineno}: {said_inside[node.lineno]}" for node in ast.walk(tree)
                   if isinstance(node, (ast.Import, ast.ImportFrom)) and id(node) not in inner and node.lineno in said_inside]
    assert at_top == [], f"these sideways imports are said to be inside a function: {at_top}"


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
GRADER_MAP = PACKAGE.parent / "docs" / "architecture.md"


def _grader_modules() -> dict[str, Path]:
    """Every grader module by dotted name (a package by its own name, for its ``__init__``)."""
    out = {}
    for p in sorted(GRADER.rglob("*.py")):
        parts = p.relative_to(GRADER.parent).with_suffix("").parts
        out[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = p
    return out


GRADER_MODULES = _grader_modules()


def _module_of(path: Path) -> str:
    return next(m for m, p in GRADER_MODULES.items() if p == path)


def _grader_imports(path: Path) -> set[str]:
    """The grader modules ``path`` imports, at the top or inside a function."""
    out = set()
    package = _module_of(path) if path.name == "__init__.py" else _module_of(path).rpartition(".")[0]
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                up = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join(up + ([node.module] if node.module else []))
            if base.split(".")[0] == "grader":
                out |= {f"{base}.{a.name}" if f"{base}.{a.name}" in GRADER_MODULES else base for a in node.names}
        elif isinstance(node, ast.Import):
            out |= {a.name for a in node.names if a.name.split(".")[0] == "grader"}
    return out & set(GRADER_MODULES)


def _third_party(path: Path) -> set[str]:
    """The top-level names of every import of ``path`` that is not the grader's."""
    out = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.level == 0:
            out.add((node.module or "").split(".")[0])
        elif isinstance(node, ast.Import):
            out |= {a.name.split(".")[0] for a in node.names}
    return out - {"grader", "__future__"}


GRAPH = {m: _grader_imports(p) - {m} for m, p in GRADER_MODULES.items()}


def _in(module: str, room: str) -> bool:
    return module == room or module.startswith(room + ".")


@pytest.mark.parametrize("path", sources(), ids=lambda p: str(p.relative_to(PACKAGE)))
def test_the_kit_never_imports_the_grader(path):
    for node in ast.walk(ast.parse(path.read_text())):
        names = [a.name for a in node.names] if isinstance(node, ast.Import) else \
            [node.module or ""] if isinstance(node, ast.ImportFrom) and node.level == 0 else []
        assert not [n for n in names if n.split(".")[0] == "grader"], f"line {node.lineno}"


def test_snakekit_grade_reaches_the_grader_through_its_entry_point():
    from snakekit import cli

    import grader.commands.grade
    import grader.lms.collect
    import grader.lms.export

    import grader.commands.nbgrader_plugins
    import grader.commands.release

    assert cli.plugin_command("grade") is grader.commands.grade.main
    assert cli.plugin_command("release") is grader.commands.release.main
    assert cli.plugin_command("collect") is grader.lms.collect.main
    # return writes the pages of hand-set scores again (a command may reach the feedback's lab part), then hands back
    assert (cli.plugin_command("return"), cli.plugin_command("export")) == (grader.commands.nbgrader_plugins.return_main,
                                                                            grader.lms.export.export_main)
    import grader.commands.lab

    assert cli.plugin_command("lab") is grader.commands.lab.main
    r = subprocess.run([sys.executable, "-m", "snakekit.cli", "grade", "--help"], capture_output=True, text=True,
                       timeout=120)
    assert r.returncode == 0 and "usage: snakekit grade" in r.stdout


def test_the_grader_has_no_import_cycle():
    done, on_path = set(), []

    def visit(m):
        if m in on_path:
            raise AssertionError("import cycle: " + " -> ".join(on_path[on_path.index(m):] + [m]))
        if m in done:
            return
        on_path.append(m)
        for n in sorted(GRAPH[m]):
            visit(n)
        on_path.pop()
        done.add(m)

    for m in sorted(GRAPH):
        visit(m)
    # the walk sees the sub-packages: the arm's session reads the gradebook through the course folder
    assert "grader.course.folder" in GRAPH["grader.arm.session"]


# The rooms' rules (docs/architecture.md, "The grader"): who may import whom.
NEVER = [
    ("grader.scoring", "grader.sandbox", "scoring judges results; it never runs a sandbox"),
    ("grader.feedback", "grader.sandbox", "the pages are made from results, never inside a sandbox"),
    ("grader.scoring", "grader.commands", "the core never imports a command"),
    ("grader.feedback", "grader.commands", "the core never imports a command"),
]
#: the grader's entry points besides its commands: the old dotted name of nbgrader's plug-ins, kept for course
#: folders made before the sub-packages (it imports grader.commands.nbgrader_plugins)
ENTRY_POINTS = {"grader.nbgrader_plugins"}
#: the core: every module but the commands, the arm's lab and those entry points
CORE = sorted(m for m in GRADER_MODULES if not (_in(m, "grader.commands") or _in(m, "grader.arm") or m in ENTRY_POINTS))
# What runs beside the student's code: the standard library, nbgrader and what nbgrader's autograde
# itself runs on (nbformat, traitlets, its gradebook's sqlalchemy, nbclient, the kernel's jupyter_client and
# ipykernel); of the kit, only its notebook client (snakekit.kernel_client, which imports nothing of the kit).
INSIDE_MAY_IMPORT = {"nbgrader", "nbformat", "traitlets", "sqlalchemy", "nbclient", "jupyter_client", "ipykernel"}
INSIDE_MAY_IMPORT_OF_THE_KIT = {"snakekit.kernel_client"}


@pytest.mark.parametrize("module", sorted(GRADER_MODULES))
def test_the_grader_s_rooms_import_only_what_they_may(module):
    imported = GRAPH[module]
    for room, banned, why in NEVER:
        if _in(module, room):
            assert not [m for m in imported if _in(m, banned)], why
    if module in CORE:
        assert not [m for m in _reached(module) if _in(m, "grader.arm") or _in(m, "grader.commands")], \
            "the core never imports the arm's lab or a command, not even through another module (the arm comes in " \
            "through grader.hooks)"


def test_the_core_is_every_module_but_the_commands_the_arm_and_the_old_plug_ins_name():
    assert {"grader", "grader.report", "grader.batch", "grader.errors"} <= set(CORE)
    assert not [m for m in CORE if _in(m, "grader.commands") or _in(m, "grader.arm")]
    assert ENTRY_POINTS <= set(GRADER_MODULES) and "grader.nbgrader_plugins" not in CORE


def _reached(module: str) -> set[str]:
    """``module`` and every grader module it imports, at any depth."""
    seen, todo = set(), [module]
    while todo:
        m = todo.pop()
        if m not in seen:
            seen.add(m)
            todo.extend(GRAPH[m])
    return seen


@pytest.mark.parametrize("module", sorted(m for m in GRADER_MODULES if _in(m, "grader.feedback") or _in(m, "grader.scoring")))
def test_the_feedback_and_the_scoring_never_reach_the_sandbox(module):
    assert not [m for m in _reached(module) if _in(m, "grader.sandbox")], \
        "scoring judges results and the pages are made from them, never inside a sandbox (not even through another " \
        "module)"


def test_what_hides_the_hidden_tests_draws_nothing():
    """grader.feedback.scrub, the code that keeps hidden tests and machine paths off the pages, stays small
    enough to read whole: it reaches no plot and no plotting library."""
    reached = _reached("grader.feedback.scrub")
    assert "grader.feedback.plot" not in reached
    libraries = set().union(*(_third_party(GRADER_MODULES[m]) for m in reached))
    assert not libraries & {"matplotlib", "PIL"}, sorted(libraries)


@pytest.mark.parametrize("module", sorted(m for m in GRADER_MODULES if _in(m, "grader.sandbox.inside")))
def test_what_runs_inside_the_sandbox_imports_only_the_standard_library_and_nbgrader(module):
    assert {m for m in GRAPH[module] if not _in(m, "grader.sandbox.inside")} <= {"grader", "grader.sandbox"}
    outside = {n for n in _third_party(GRADER_MODULES[module]) if n not in sys.stdlib_module_names} - {"snakekit"}
    assert outside <= INSIDE_MAY_IMPORT, f"{module} imports {sorted(outside - INSIDE_MAY_IMPORT)}"
    kit = _kit_imports(GRADER_MODULES[module])   # no course data; of the kit its notebook client alone
    assert kit <= INSIDE_MAY_IMPORT_OF_THE_KIT, f"{module} imports {sorted(kit - INSIDE_MAY_IMPORT_OF_THE_KIT)}"


def _kit_imports(path: Path) -> set[str]:
    """The kit modules ``path`` imports, by their whole names (``snakekit`` for the package itself)."""
    out = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.level == 0 and (node.module or "").split(".")[0] == "snakekit":
            out |= {node.module} if node.module != "snakekit" else {f"snakekit.{a.name}" for a in node.names}
        elif isinstance(node, ast.Import):
            out |= {a.name for a in node.names if a.name.split(".")[0] == "snakekit"}
    return out


def test_the_kit_s_module_the_sandbox_may_import_imports_nothing_of_the_kit_and_no_course_data():
    for name in INSIDE_MAY_IMPORT_OF_THE_KIT:
        path = PACKAGE / f"{name.split('.', 1)[1]}.py"
        assert [i for i, _, _ in imports(path) if i is not None] == []
        outside = {e for _, e, _ in imports(path) if e is not None and e not in sys.stdlib_module_names} - {"__future__"}
        assert outside <= INSIDE_MAY_IMPORT, sorted(outside - INSIDE_MAY_IMPORT)


@pytest.mark.parametrize("module", sorted(GRADER_MODULES))
def test_every_grader_module_is_on_the_map(module):
    assert f"`{module}`" in GRADER_MAP.read_text(), f"docs/architecture.md names every grader module: {module}"


def test_the_map_names_no_grader_module_that_is_gone():
    named = set(re.findall(r"`(grader(?:\.\w+)+)`", GRADER_MAP.read_text()))
    assert named and named <= set(GRADER_MODULES) | {m + "." + n for m in GRADER_MODULES for n in ("main",)}, \
        sorted(named - set(GRADER_MODULES))


def _classes(path: Path):
    return [n for n in ast.walk(ast.parse(path.read_text())) if isinstance(n, ast.ClassDef)]


@pytest.mark.parametrize("module", sorted(GRADER_MODULES))
def test_every_grader_exception_lives_in_grader_errors(module):
    """As Python sees it, whatever the class is called or written as: every class a grader module defines that is
    an exception (Ctrl-C's KeyboardInterrupt too) is defined in grader/errors.py."""
    if module == "grader.errors":
        return
    mod = importlib.import_module(module)
    defined = [n for n, c in vars(mod).items() if inspect.isclass(c) and issubclass(c, BaseException)
               and c.__module__ == module]
    assert defined == [], f"{module} defines {defined}: exception classes live in grader/errors.py"
    # and none inside a function or a class, where the module's names do not show it
    nested = [c.name for c in _classes(GRADER_MODULES[module]) if c.name not in vars(mod)]
    assert not [n for n in nested if n.endswith(("Error", "Interrupted", "Exception"))], nested


def test_the_grader_s_exceptions_are_in_the_kit_s_tree_and_shadow_no_built_in():
    """Its errors derive from SnakekitError; Ctrl-C between two students (Interrupted and one subclass per
    command) from KeyboardInterrupt, so that what catches errors does not catch it."""
    mod = importlib.import_module("grader.errors")
    classes = [c for c in vars(mod).values() if inspect.isclass(c) and c.__module__ == "grader.errors"]
    assert len(classes) >= 9
    for c in classes:
        if issubclass(c, mod.Interrupted):
            assert issubclass(c, KeyboardInterrupt) and not issubclass(c, Exception), c
        else:
            assert issubclass(c, errors.SnakekitError), c
        assert c.__name__ not in dir(builtins), f"{c.__name__} shadows a built-in"


#: the kit's modules the grader imports (docs/architecture.md names each), and those only its arm's lab imports
KIT_USED_BY_THE_GRADER = {"cells", "cli", "closeness", "errors", "handin", "host", "kernel_client", "kinematics",
                          "mistakes", "model", "trajectory", "validate", "verdicts", "watch"}
KIT_USED_BY_THE_ARM = {"collision", "profile_planner", "sim"}


def test_the_map_names_every_kit_module_the_grader_imports():
    used = {m: set() for m in ("core", "arm")}
    for module, path in GRADER_MODULES.items():
        kit = {k.split(".")[1] for k in _kit_imports(path) if k.count(".") >= 1}
        kit = {k for k in kit if (PACKAGE / f"{k}.py").exists() or (PACKAGE / k).is_dir()}
        used["arm" if _in(module, "grader.arm") else "core"] |= kit
    assert used["core"] == KIT_USED_BY_THE_GRADER, sorted(used["core"] ^ KIT_USED_BY_THE_GRADER)
    assert used["arm"] - used["core"] == KIT_USED_BY_THE_ARM, sorted((used["arm"] - used["core"]) ^ KIT_USED_BY_THE_ARM)
    text = " ".join(GRADER_MAP.read_text().split())
    said = text[text.index("The grader uses the kit's"):].split(". ", 1)[0]
    named = set(re.findall(r"`(\w+)`", said))
    assert KIT_USED_BY_THE_GRADER | KIT_USED_BY_THE_ARM <= named, sorted(KIT_USED_BY_THE_GRADER | KIT_USED_BY_THE_ARM - named)
    # and what the fork server imports by name, each named where the page says so
    from grader.sandbox.forkserver import PRELOAD

    preloaded = {m.split(".")[1] for m in PRELOAD if m.startswith("snakekit.")}
    warm = text[text.index("The fork server's warm start imports by name"):].split(". ", 1)[0]
    assert preloaded == set(re.findall(r"`(\w+)`", warm)) - {"PRELOAD"}, sorted(preloaded)


def _strings(path: Path) -> list[tuple[int, str]]:
    """The string constants of ``path`` that are not docstrings."""
    tree = ast.parse(path.read_text())
    docs = {id(n.body[0].value) for n in ast.walk(tree)
            if isinstance(n, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)) and n.body
            and isinstance(n.body[0], ast.Expr) and isinstance(n.body[0].value, ast.Constant)}
    return [(n.lineno, n.value) for n in ast.walk(tree)
            if isinstance(n, ast.Constant) and isinstance(n.value, str) and id(n) not in docs]


@pytest.mark.parametrize("module", sorted(m for m in GRADER_MODULES if m != "grader.markup"))
def test_nbgrader_s_markers_are_written_only_in_grader_markup(module):
    found = [line for line, s in _strings(GRADER_MODULES[module]) if re.search(r"(BEGIN|END) (HIDDEN TESTS|SOLUTION)", s)]
    assert found == [], f"lines {found}: use grader.markup"


@pytest.mark.parametrize("module", sorted(GRADER_MODULES))
def test_no_private_name_crosses_a_grader_module(module):
    """Not from another grader module, nor from the kit."""
    bad = [f"line {n.lineno}: {a.name} from {n.module}" for n in ast.walk(ast.parse(GRADER_MODULES[module].read_text()))
           if isinstance(n, ast.ImportFrom) and (n.module or "").split(".")[0] in ("grader", "snakekit") for a in n.names
           if a.name.startswith("_")]
    assert bad == []


@pytest.mark.parametrize("path", sorted(GRADER.rglob("*.py")), ids=lambda p: str(p.relative_to(GRADER)))
def test_no_grader_module_is_over_600_lines(path):
    assert len(path.read_text().splitlines()) <= 600
