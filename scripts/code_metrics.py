"""Size figures of the code, for refactorings that promise shorter functions and shorter
parameter lists (issue 26): functions over a line limit, the longest functions, the
longest parameter lists.

    .venv/bin/python scripts/code_metrics.py                 # riskcore datasets sampler app
    .venv/bin/python scripts/code_metrics.py sampler --top 15 --limit 50

A function's length is its source lines from ``def`` (decorators excluded) to its last
line, docstring and comments included (and, in brackets, without its docstring); its
parameters are every name it takes (``self``/``cls`` excluded, ``*args``/``**kwargs``
counted once each). Nested functions count as functions of their own (and inside their
parent's length).
"""

from __future__ import annotations

import argparse
import ast
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("riskcore", "datasets", "sampler", "app")


@dataclass(frozen=True)
class Function:
    where: str  # path:line
    name: str  # qualified within its module
    lines: int
    params: int
    code: int  # lines without the docstring


def _params(node: ast.FunctionDef | ast.AsyncFunctionDef) -> int:
    a = node.args
    names = [*a.posonlyargs, *a.args, *a.kwonlyargs]
    n = len(names) + (a.vararg is not None) + (a.kwarg is not None)
    if names and names[0].arg in ("self", "cls"):
        n -= 1
    return n


def functions(path: Path) -> list[Function]:
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    rel = path.relative_to(ROOT)
    out: list[Function] = []

    def visit(node: ast.AST, prefix: str) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.FunctionDef | ast.AsyncFunctionDef):
                name = f"{prefix}{child.name}"
                end = child.end_lineno or child.lineno
                lines = end - child.lineno + 1
                doc = child.body[0]
                if (isinstance(doc, ast.Expr) and isinstance(doc.value, ast.Constant)
                        and isinstance(doc.value.value, str)):
                    lines_doc = (doc.end_lineno or doc.lineno) - doc.lineno + 1
                else:
                    lines_doc = 0
                out.append(Function(f"{rel}:{child.lineno}", name, lines, _params(child),
                                    lines - lines_doc))
                visit(child, f"{name}.")
            elif isinstance(child, ast.ClassDef):
                visit(child, f"{prefix}{child.name}.")
            else:
                visit(child, prefix)

    visit(tree, "")
    return out


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("packages", nargs="*", default=list(PACKAGES))
    parser.add_argument("--limit", type=int, default=50, help="long = more lines than this")
    parser.add_argument("--top", type=int, default=10)
    args = parser.parse_args(argv)
    for pkg in args.packages:
        found = [f for p in sorted((ROOT / pkg).rglob("*.py")) for f in functions(p)]
        long_ = [f for f in found if f.lines > args.limit]
        long_code = [f for f in found if f.code > args.limit]
        print(f"== {pkg}: {len(found)} functions, {len(long_)} over {args.limit} lines "
              f"({len(long_code)} without docstrings), max parameters "
              f"{max((f.params for f in found), default=0)}")
        print("  longest:")
        for f in sorted(found, key=lambda f: (-f.lines, f.where))[: args.top]:
            print(f"    {f.lines:4d} lines ({f.code:3d} code)  {f.name}  ({f.where})")
        print("  most parameters:")
        for f in sorted(found, key=lambda f: (-f.params, f.where))[: args.top]:
            print(f"    {f.params:4d} params {f.name}  ({f.where})")


if __name__ == "__main__":
    main()
