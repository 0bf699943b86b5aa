"""The layers declared in pyproject.toml ([tool.importlinter]) hold: studies use only the public
API of taichi_star, taichi_star never imports studies, no study imports another, no import
cycles between sibling modules."""

import ast
import importlib
import inspect
import os
import shutil
import subprocess
import sys
import types
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent


def test_import_contracts_are_kept():
    command = shutil.which("lint-imports") or str(Path(sys.executable).with_name("lint-imports"))
    if not Path(command).exists():
        pytest.fail("lint-imports not found: pip install -e '.[test]' installs import-linter")
    run = subprocess.run([command, "--no-cache"], cwd=REPO, capture_output=True, text=True,
                         env=dict(os.environ, PYTHONPATH=str(REPO)))
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-2000:]
    assert "BROKEN" not in run.stdout


def test_every_study_is_in_the_independence_contract():
    """The contract lists the studies by name: a study added without it could import another."""
    from studies import study_names

    tomllib = pytest.importorskip("tomllib")     # Python ≥ 3.11

    contracts = tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["importlinter"][
        "contracts"]
    (independent,) = [c for c in contracts if c["name"] == "no study imports another study"]
    assert sorted(independent["modules"]) == [f"studies.{name}" for name in study_names()]


# simd.py is a measured prototype of the engine's own LU and force terms: it reaches the
# engine's plan and compiler settings on purpose (its module docstring), and is exempt here
NAMES_CHECK_EXEMPT = ("simd.py",)


def module_source(module: str) -> Path:
    """The source file of a taichi_star module or package, found without importing it (some
    need an optional extra: the batch's Dask cluster)."""
    base = REPO.joinpath(*module.split("."))
    return base / "__init__.py" if base.is_dir() else base.with_suffix(".py")


def public_names(module: str):
    """The module's `__all__` (a literal list), read from its source; None where it has none."""
    for node in ast.parse(module_source(module).read_text()).body:
        if isinstance(node, ast.Assign) and any(getattr(target, "id", None) == "__all__"
                                                for target in node.targets):
            return set(ast.literal_eval(node.value))
    return None


def taichi_star_names(tree: ast.Module):
    """(line, module, name) of every name a study takes from taichi_star: each `from
    taichi_star... import name` and each attribute of a taichi_star module bound to a name
    (`import taichi_star`, `from taichi_star import metrics`, then `metrics.speed_error`)."""
    modules = {}
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and (node.module or "").split(".")[0] == "taichi_star":
            for alias in node.names:
                yield node.lineno, node.module, alias.name
                if module_source(f"{node.module}.{alias.name}").exists():
                    modules[alias.asname or alias.name] = f"{node.module}.{alias.name}"
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.split(".")[0] == "taichi_star":  # bare, it binds the package
                    modules[alias.asname or "taichi_star"] = (alias.name if alias.asname
                                                              else "taichi_star")
    # a chain (taichi_star.runtime.PARALLEL_LOOP_MINIMUM) is followed from its outermost
    # attribute down through each module it names, every name on the way checked (only its
    # first was: a review, 2026-12)
    inner = {id(node.value) for node in ast.walk(tree) if isinstance(node, ast.Attribute)}
    for node in ast.walk(tree):
        if not isinstance(node, ast.Attribute) or id(node) in inner:
            continue
        parts, root = [], node
        while isinstance(root, ast.Attribute):
            parts.insert(0, root.attr)
            root = root.value
        if not (isinstance(root, ast.Name) and root.id in modules):
            continue
        module = modules[root.id]
        for part in parts:
            yield node.lineno, module, part
            if not module_source(f"{module}.{part}").exists():
                break
            module = f"{module}.{part}"


def hidden_names(tree: ast.Module):
    """"line: module.name" of each name in `taichi_star_names` that is not public: not in its
    module's `__all__`, or a module without one."""
    hidden = []
    for line, module, name in taichi_star_names(tree):
        if module_source(f"{module}.{name}").exists():
            if public_names(f"{module}.{name}") is None:
                hidden.append(f"{line}: {module}.{name} (a module without __all__)")
        elif name not in (public_names(module) or set()):
            hidden.append(f"{line}: {module}.{name}")
    return hidden


def test_studies_take_only_public_names_from_taichi_star():
    """The import contracts see modules, not names: a study importing an internal through a
    public module's namespace (`from taichi_star.sensitivities import COMPONENT_HEIGHTS`, a
    params constant) kept them (an audit). Each name a study takes from a taichi_star module
    is in that module's `__all__` (what docs/api.md documents, the names studies use among
    them); a module taken as a name declares one."""
    hidden = [f"studies/{path.name}:{name}" for path in sorted((REPO / "studies").glob("*.py"))
              if path.name not in NAMES_CHECK_EXEMPT
              for name in hidden_names(ast.parse(path.read_text()))]
    assert hidden == []


@pytest.mark.parametrize("source, hidden", [
    ("from taichi_star.sensitivities import COMPONENT_HEIGHTS", True),
    ("from taichi_star import COMPONENT_HEIGHTS", False),
    ("from taichi_star import model", True),                  # an engine module: no __all__
    ("from taichi_star import metrics\nmetrics.speed_error", False),
    ("import taichi_star.runtime as runtime\nruntime.PARALLEL_LOOP_MINIMUM", True),
    ("import taichi_star\ntaichi_star.simulate", False),
    ("import taichi_star.runtime\ntaichi_star.simulate", False),
    # a chain through a public module to a name it does not publish, and one it does
    ("import taichi_star.runtime\ntaichi_star.runtime.PARALLEL_LOOP_MINIMUM", True),
    ("import taichi_star\ntaichi_star.metrics.speed_error", False),
    ("import taichi_star\ntaichi_star.model.build_model", True),
])
def test_the_names_check_sees_imports_and_module_attributes(source, hidden):
    """The check above on one case each: a name re-exported by accident, a module without
    `__all__`, a module's attribute that is not public."""
    assert bool(hidden_names(ast.parse(source))) == hidden


TAICHI_DECORATORS = ("ti.kernel", "ti.func", "ti.real_func")


def kernel_global_reads(tree: ast.Module, module_names):
    """(line, function, name) of each name that a @ti.kernel or @ti.func body of `tree` reads
    and that is none of its arguments or locals but one of `module_names` (the module's own
    top-level names), and of each attribute chain rooted at one ("Term.X", "physics.base.X";
    dotted)."""
    for function in ast.walk(tree):
        if not (isinstance(function, ast.FunctionDef) and any(
                ast.unparse(decorator).split("(")[0] in TAICHI_DECORATORS
                for decorator in function.decorator_list)):
            continue
        local = {argument.arg for argument in function.args.args + function.args.kwonlyargs}
        local |= {node.id for node in ast.walk(function)
                  if isinstance(node, ast.Name) and isinstance(node.ctx, ast.Store)}
        body = [node for statement in function.body for node in ast.walk(statement)]
        inner = {id(node.value) for node in body if isinstance(node, ast.Attribute)}
        for node in body:
            chain = []
            while isinstance(node, ast.Attribute) and id(node) not in inner:
                chain, node = [node.attr, *chain], node.value
                inner.add(id(node))
            if isinstance(node, ast.Name) and isinstance(node.ctx, ast.Load) \
                    and node.id in module_names and node.id not in local:
                yield node.lineno, function.name, ".".join([node.id, *chain])


def compile_time_constant(value) -> bool:
    """Code (a function, a class, a module) or an immutable value (a number, a string, a tuple
    of such): what Taichi may bake into a kernel when it compiles it."""
    if callable(value) or inspect.ismodule(value):
        return True
    if isinstance(value, tuple):
        return all(compile_time_constant(item) for item in value)
    return isinstance(value, (bool, int, float, str))


def mutable_kernel_globals(module, tree: ast.Module, rebound_names):
    """"line function: name" of each module global a kernel of `module` reads that is not a
    compile-time constant, or that the package rebinds (`rebound_names`): Taichi bakes the
    value it finds at the kernel's first compilation into the kernel, so a later change would
    be silently ignored."""
    found = []
    for line, function, name in kernel_global_reads(tree, set(vars(module))):
        value = module
        for part in name.split("."):
            value = getattr(value, part, MISSING)
        if value is MISSING or name.split(".")[-1] in rebound_names \
                or not compile_time_constant(value):
            found.append(f"{line} {function}: {name}")
    return found


MISSING = object()
"""An attribute a kernel reads that its module does not have at import (made later)."""


def rebound_globals(trees) -> set:
    """The names that any of `trees` declares `global` (to rebind them), assigns as a
    module's or a class's attribute (`module.NAME = ...`) or sets by `setattr(x, "NAME", ...)`."""
    names = set()
    for tree in trees:
        for node in ast.walk(tree):
            if isinstance(node, ast.Global):
                names.update(node.names)
            elif isinstance(node, ast.Call) and ast.unparse(node.func) == "setattr" \
                    and len(node.args) > 1 and isinstance(node.args[1], ast.Constant):
                names.add(node.args[1].value)
            elif isinstance(node, (ast.Assign, ast.AugAssign)):
                targets = node.targets if isinstance(node, ast.Assign) else [node.target]
                names.update(target.attr for target in targets
                             if isinstance(target, ast.Attribute)
                             and isinstance(target.value, ast.Name)
                             and target.value.id != "self")
    return names


def test_kernels_read_no_module_global_that_can_change():
    """Kernels get what varies as arguments and fields; a module global a kernel reads must be
    code or an immutable constant that nothing rebinds (the status codes, the terms' tuples,
    N_ACTUATORS): Taichi compiles its value in."""
    sources = sorted((REPO / "taichi_star").rglob("*.py"))
    trees = {path: ast.parse(path.read_text()) for path in sources}
    rebound = rebound_globals(trees.values())
    found, read = [], set()
    for path, tree in trees.items():
        if not any(ast.unparse(decorator).split("(")[0] in TAICHI_DECORATORS
                   for node in ast.walk(tree) if isinstance(node, ast.FunctionDef)
                   for decorator in node.decorator_list):
            continue                   # no kernel (and perhaps an optional extra's imports)
        name = ".".join(path.relative_to(REPO).with_suffix("").parts).removesuffix(".__init__")
        module = importlib.import_module(name)
        read |= {global_name for _, _, global_name in kernel_global_reads(tree, set(vars(module)))}
        found += [f"{name}:{item}" for item in mutable_kernel_globals(module, tree, rebound)]
    assert found == []
    # the check saw the kernels' constants (it would pass seeing nothing)
    assert {"N_ACTUATORS", "STATUS_OK", "ALL_TERMS", "LAGGED_MAX_AGE"} <= read


@pytest.mark.parametrize("source, flagged", [
    ("LIMIT = 3.0\n@ti.func\ndef f(x):\n    return x * LIMIT", []),
    ("GAINS = [1.0, 2.0]\n@ti.func\ndef f(x):\n    return x * GAINS[0]", ["4 f: GAINS"]),
    ("LIMIT = 3.0\n@ti.kernel\ndef f(x: float):\n    return x * LIMIT\n"
     "def g():\n    global LIMIT\n    LIMIT = 4.0", ["4 f: LIMIT"]),
    # an argument or a local of the same name is not the global
    ("GAINS = [1.0]\n@ti.func\ndef f(GAINS):\n    return GAINS[0]", []),
    ("GAINS = [1.0]\n@ti.func\ndef f(x):\n    GAINS = x\n    return GAINS", []),
    ("GAINS = [1.0]\ndef f(x):\n    return GAINS[0]", []),          # no kernel
    # a class's mutable attribute, and an immutable one rebound by setattr
    ("class C:\n    X = [1.0]\n@ti.func\ndef f(x):\n    return x * C.X[0]", ["5 f: C.X"]),
    ("class C:\n    X = 1.0\n@ti.func\ndef f(x):\n    return x * C.X\n"
     "def g():\n    setattr(C, 'X', 2.0)", ["5 f: C.X"]),
    ("class C:\n    X = 1.0\n@ti.func\ndef f(x):\n    return x * C.X", []),
])
def test_the_kernel_globals_check_on_one_case_each(source, flagged):
    tree = ast.parse(source)
    module = types.ModuleType("case")
    module.ti = types.SimpleNamespace(kernel=lambda f: f, func=lambda f: f)
    exec(compile(tree, "case", "exec"), vars(module))
    assert mutable_kernel_globals(module, tree, rebound_globals([tree])) == flagged
