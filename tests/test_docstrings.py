"""Docstrings are the API reference (``mkdocs build --strict`` in CI is generated from them).

* every public name (each part's ``__all__``) and every public method of a public class has one;
* every public function and method of the package is numpydoc: each of its parameters in a
  ``Parameters`` section, what it returns in ``Returns`` (``Yields`` for a generator); a
  class's constructor parameters in the class docstring (dataclasses document their fields
  as attribute docstrings instead).

Run as a script on files to list what is missing: ``python tests/test_docstrings.py FILE...``.
"""

import ast
import importlib
import inspect
import re
import sys
from pathlib import Path

import pytest

PARTS = ("hystmpc.models", "hystmpc.plants", "hystmpc.mpc", "hystmpc.mpc.codegen", "hystmpc.experiments",
         "hystmpc.experiments.baselines")
ROOT = Path(__file__).resolve().parent.parent
FOLDERS = ("models", "plants", "mpc", "experiments")


def _undocumented(part: str) -> list[str]:
    module = importlib.import_module(part)
    missing = []
    for name in module.__all__:
        obj = getattr(module, name)
        if (inspect.isclass(obj) or inspect.isfunction(obj)) and not (obj.__doc__ or "").strip():
            missing.append(name)
        if inspect.isclass(obj):
            for attr, value in vars(obj).items():
                method = value.__func__ if isinstance(value, (staticmethod, classmethod)) else value
                if (not attr.startswith("_") and inspect.isfunction(method) and method.__name__ != "<lambda>"
                        and not (method.__doc__ or "").strip()):
                    missing.append(f"{name}.{attr}")
    return missing


@pytest.mark.parametrize("part", PARTS)
def test_every_public_name_has_a_docstring(part):
    assert _undocumented(part) == []


def _section(doc: str, title: str) -> str | None:
    """The body of numpydoc section ``title`` (None when there is none)."""
    match = re.search(rf"^[ \t]*{title}\n[ \t]*-{{{len(title)}}}\n(.*?)(?=^[ \t]*\w[\w ]*\n[ \t]*-{{3,}}\n|\Z)",
                      doc, re.S | re.M)
    return match.group(1) if match else None


def _documented_names(body: str) -> set[str]:
    """Names of the entries of a Parameters section (``a : int``, ``a, b : float``, ``*args``, ``x``)."""
    names = set()
    for line in body.splitlines():
        if line and not line[0].isspace():
            head = line.split(" : ", 1)[0]
            names |= {n.strip().lstrip("*") for n in head.split(",")}
    return names


def _decorators(node) -> set[str]:
    return {d.id if isinstance(d, ast.Name) else d.attr if isinstance(d, ast.Attribute) else "" for d in
            node.decorator_list}


def _returns_value(node) -> tuple[bool, bool]:
    """Whether a function returns a value, and whether it yields (nested functions not counted)."""
    returns = yields = False
    stack = list(node.body)
    while stack:
        child = stack.pop()
        if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda, ast.ClassDef)):
            continue
        if isinstance(child, ast.Return) and child.value is not None and not (
                isinstance(child.value, ast.Constant) and child.value.value is None):
            returns = True
        if isinstance(child, (ast.Yield, ast.YieldFrom)):
            yields = True
        stack.extend(ast.iter_child_nodes(child))
    return returns, yields


def _parameters(node) -> list[str]:
    args = node.args
    names = [a.arg for a in (*args.posonlyargs, *args.args, *args.kwonlyargs)]
    names += [a.arg for a in (args.vararg, args.kwarg) if a is not None]
    return [n for n in names if n not in ("self", "cls")]


def _is_dataclass(node: ast.ClassDef) -> bool:
    return any("dataclass" in ast.unparse(d) for d in node.decorator_list)


def _function_problems(node, where: str, doc: str | None) -> list[str]:
    decorators = _decorators(node)
    if decorators & {"property", "overload", "setter", "cached_property"} or doc is None:
        return []  # a missing docstring is the other test's (or ruff's) to report
    problems = []
    parameters = _parameters(node)
    if parameters:
        body = _section(doc, "Parameters")
        if body is None:
            problems.append(f"{where}: no Parameters section ({', '.join(parameters)})")
        else:
            missing = [p for p in parameters if p not in _documented_names(body)]
            if missing:
                problems.append(f"{where}: Parameters lacks {', '.join(missing)}")
    returns, yields = _returns_value(node)
    if yields and _section(doc, "Yields") is None:
        problems.append(f"{where}: no Yields section")
    elif returns and not yields and _section(doc, "Returns") is None:
        problems.append(f"{where}: no Returns section")
    return problems


def numpydoc_problems(path: Path) -> list[str]:
    """What the public functions, methods and constructors of one source file leave undocumented."""
    tree = ast.parse(path.read_text())
    name = str(path.relative_to(ROOT)) if path.is_absolute() and ROOT in path.parents else str(path)
    problems = []

    def visit(parent, prefix: str) -> None:
        for node in ast.iter_child_nodes(parent):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and not node.name.startswith("_"):
                where = f"{name}:{node.lineno} {prefix}{node.name}"
                problems.extend(_function_problems(node, where, ast.get_docstring(node)))
            elif isinstance(node, ast.ClassDef) and not node.name.startswith("_"):
                init = next((n for n in node.body if isinstance(n, ast.FunctionDef) and n.name == "__init__"), None)
                if init is not None and not _is_dataclass(node):
                    doc = ast.get_docstring(init) or ast.get_docstring(node)
                    where = f"{name}:{node.lineno} class {prefix}{node.name}"
                    problems.extend(_function_problems(init, where, doc))
                visit(node, f"{prefix}{node.name}.")

    visit(tree, "")
    return problems


def _package_files() -> list[Path]:
    return sorted(p for folder in FOLDERS for p in (ROOT / folder).rglob("*.py")
                  if not any(part.startswith("_") and part != "__init__.py" for part in p.relative_to(ROOT).parts))


@pytest.mark.parametrize("folder", FOLDERS)
def test_every_public_function_is_numpydoc(folder):
    problems = [p for path in _package_files() if path.relative_to(ROOT).parts[0] == folder
                for p in numpydoc_problems(path)]
    assert problems == [], f"{len(problems)} undocumented:\n" + "\n".join(problems)


def test_the_numpydoc_check_finds_an_undocumented_parameter_and_return(tmp_path):
    source = tmp_path / "example.py"
    source.write_text('def f(a, b):\n    """Sum.\n\n    Parameters\n    ----------\n    a : float\n'
                      '        One.\n    """\n    return a + b\n\n\nclass C:\n    """A thing."""\n\n'
                      '    def __init__(self, x):\n        self.x = x\n')
    problems = numpydoc_problems(source)
    assert any("f: Parameters lacks b" in p for p in problems)
    assert any("f: no Returns section" in p for p in problems)
    assert any("class C: no Parameters section (x)" in p for p in problems)


if __name__ == "__main__":
    found = [p for arg in sys.argv[1:] for p in numpydoc_problems(Path(arg).resolve())]
    print("\n".join(found) or "no problems")
    print(f"{len(found)} problems", file=sys.stderr)
