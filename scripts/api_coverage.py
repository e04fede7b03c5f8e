"""Count the package's public functions and methods with a docstring and with full type annotations.

    python scripts/api_coverage.py                       # the two percentages for dolfinx_nnqem
    python scripts/api_coverage.py --missing             # and, per file, what lacks either
    python scripts/api_coverage.py dolfinx_nnqem/material --missing     # one folder or file only
    python scripts/api_coverage.py --min-docstrings 90 --min-annotations 95   # exit 1 below either

What counts, read from the source with ``ast`` (nothing is imported):

- a function at a module's top level, or a method in the body of a class (nested classes too);
- public only: a function, method or class whose name starts with ``_`` is skipped (dunder methods
  too: NumPy style documents ``__init__``'s parameters in the class docstring), and so is every module
  or folder whose name starts with ``_``, except ``__init__.py``;
- a docstring: ``ast.get_docstring`` is not empty;
- annotated: every parameter (``*args`` and ``**kwargs`` too) and the return value are annotated; a
  method's first parameter ``self`` or ``cls`` needs none (unless it is a ``staticmethod``), and
  ``__init__`` needs no return annotation. A property, and each of its setters, is a method.

CI runs it with the thresholds the package meets (``--min-docstrings``, ``--min-annotations``).
"""

from __future__ import annotations

import argparse
import ast
import sys
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "dolfinx_nnqem"

Function = ast.FunctionDef | ast.AsyncFunctionDef


@dataclass(frozen=True)
class PublicFunction:
    """One public function or method, as the counts see it."""

    path: Path
    line: int
    name: str  # qualified within its module: "Class.method" or "function"
    has_docstring: bool
    is_annotated: bool


def is_public_module(path: Path, folder: Path) -> bool:
    """Whether no part of ``path`` below ``folder`` starts with ``_`` (``__init__.py`` excepted)."""
    parts = path.relative_to(folder).parts
    return not any(part.startswith("_") and part != "__init__.py" for part in parts)


def modules_under(path: Path) -> list[Path]:
    """The public modules of a folder (searched recursively), or ``[path]`` for a single file."""
    if path.is_file():
        return [path]
    return [module for module in sorted(path.rglob("*.py")) if is_public_module(module, path)]


def is_staticmethod(node: Function) -> bool:
    """Whether ``node`` is decorated with ``@staticmethod``."""
    return any(isinstance(decorator, ast.Name) and decorator.id == "staticmethod"
               for decorator in node.decorator_list)


def is_annotated(node: Function, is_method: bool) -> bool:
    """Whether every parameter and the return value of ``node`` carry an annotation.

    Parameters
    ----------
    node
        The function's definition.
    is_method
        Whether it is defined in a class body: its first parameter, when named ``self`` or ``cls``
        and the method is not a ``staticmethod``, is then exempt.
    """
    parameters = node.args.posonlyargs + node.args.args + node.args.kwonlyargs
    if is_method and parameters and parameters[0].arg in ("self", "cls") and not is_staticmethod(node):
        parameters = parameters[1:]
    parameters += [p for p in (node.args.vararg, node.args.kwarg) if p is not None]
    returns_annotated = node.returns is not None or node.name == "__init__"
    return returns_annotated and all(p.annotation is not None for p in parameters)


def public_functions_of(body: list[ast.stmt], path: Path, prefix: str = "",
                        in_class: bool = False) -> Iterator[PublicFunction]:
    """The public functions of a module's body, and the public methods of its public classes.

    Parameters
    ----------
    body
        The statements of a module or of a class.
    path
        The module's file (for the report).
    prefix
        The qualified name of the enclosing class, with a trailing dot ("" at module level).
    in_class
        Whether ``body`` is a class body.
    """
    for node in body:
        if isinstance(node, ast.ClassDef) and not node.name.startswith("_"):
            yield from public_functions_of(node.body, path, f"{prefix}{node.name}.", in_class=True)
        elif isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and not node.name.startswith("_"):
            yield PublicFunction(path, node.lineno, prefix + node.name,
                                 has_docstring=bool(ast.get_docstring(node)),
                                 is_annotated=is_annotated(node, in_class))


def public_functions(paths: Sequence[Path]) -> list[PublicFunction]:
    """Every public function and method of the public modules found under ``paths``."""
    found: list[PublicFunction] = []
    for path in paths:
        for module in modules_under(path):
            found.extend(public_functions_of(ast.parse(module.read_text(), str(module)).body, module))
    return found


def percentage(count: int, total: int) -> float:
    """``100 count / total``, and 100 when there is nothing to count."""
    return 100.0 * count / total if total else 100.0


def shown(path: Path) -> str:
    """``path`` relative to the repository when it lies in it (shorter lines in the report)."""
    resolved = path.resolve()
    return str(resolved.relative_to(ROOT)) if resolved.is_relative_to(ROOT) else str(path)


def report_missing(functions: Sequence[PublicFunction]) -> None:
    """Print, file by file, the functions without a docstring or without full annotations."""
    by_file: dict[Path, list[PublicFunction]] = {}
    for function in functions:
        by_file.setdefault(function.path, []).append(function)
    for path, in_file in by_file.items():
        lacking = [f for f in in_file if not (f.has_docstring and f.is_annotated)]
        if not lacking:
            continue
        undocumented = sum(not f.has_docstring for f in in_file)
        unannotated = sum(not f.is_annotated for f in in_file)
        print(f"{shown(path)}: {len(in_file)} public, {undocumented} without docstring, "
              f"{unannotated} not annotated")
        for f in lacking:
            what = ", ".join(label for label, lacks in (("docstring", not f.has_docstring),
                                                         ("annotations", not f.is_annotated)) if lacks)
            print(f"    {f.line:5d} {f.name}: no {what}")


def main(argv: Sequence[str] | None = None) -> int:
    """Print the percentages (and with ``--missing`` what is missing); 1 when below a threshold."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("paths", nargs="*", type=Path, default=[PACKAGE],
                        help="folders (searched recursively) or files; default: the package")
    parser.add_argument("--missing", action="store_true",
                        help="list, per file, the functions without a docstring or annotations")
    parser.add_argument("--min-docstrings", type=float, default=0.0, metavar="PERCENT",
                        help="exit 1 when fewer public functions have a docstring")
    parser.add_argument("--min-annotations", type=float, default=0.0, metavar="PERCENT",
                        help="exit 1 when fewer public functions are fully annotated")
    args = parser.parse_args(argv)
    for path in args.paths:
        if not path.exists():
            parser.error(f"{path}: no such file or folder")

    functions = public_functions(args.paths)
    if args.missing:
        report_missing(functions)
    documented = percentage(sum(f.has_docstring for f in functions), len(functions))
    annotated = percentage(sum(f.is_annotated for f in functions), len(functions))
    print(f"public functions {len(functions)}: docstrings {documented:.1f} %, "
          f"annotations {annotated:.1f} %")

    failures = []
    if documented < args.min_docstrings:
        failures.append(f"docstrings {documented:.1f} % < {args.min_docstrings:g} %")
    if annotated < args.min_annotations:
        failures.append(f"annotations {annotated:.1f} % < {args.min_annotations:g} %")
    for failure in failures:
        print(f"[api_coverage] below the threshold: {failure}", file=sys.stderr)
    return 1 if failures else 0


if __name__ == "__main__":
    raise SystemExit(main())
