"""How many of a package's type annotations mention ``Any`` (issue 26's typed-boundaries figure).

    python scripts/count_any.py [PACKAGE ...] [--rev GIT_REV]

Counts every annotation (parameters, returns, annotated assignments) in the package's .py
files, and those whose text contains the name ``Any`` (``dict[str, Any]`` counted apart).
With ``--rev`` it reads the files of that commit (``git show``) instead of the work tree.
"""

from __future__ import annotations

import argparse
import ast
import subprocess
from pathlib import Path


def _sources(package: str, rev: str | None) -> list[tuple[str, str]]:
    if rev is None:
        files = sorted(Path(package).rglob("*.py"))
        return [(str(p), p.read_text(encoding="utf-8")) for p in files]
    names = subprocess.run(["git", "ls-tree", "-r", "--name-only", rev, package],
                           check=True, capture_output=True, text=True).stdout.split()
    return [(n, subprocess.run(["git", "show", f"{rev}:{n}"], check=True, capture_output=True,
                               text=True).stdout) for n in names if n.endswith(".py")]


def _annotations(tree: ast.AST) -> list[ast.expr]:
    out: list[ast.expr] = []
    for node in ast.walk(tree):
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
            args = node.args
            for a in [*args.posonlyargs, *args.args, *args.kwonlyargs, args.vararg, args.kwarg]:
                if a is not None and a.annotation is not None:
                    out.append(a.annotation)
            if node.returns is not None:
                out.append(node.returns)
        elif isinstance(node, ast.AnnAssign):
            out.append(node.annotation)
    return out


def count(package: str, rev: str | None = None) -> dict[str, int]:
    total = any_ = dict_any = 0
    for _name, text in _sources(package, rev):
        for ann in _annotations(ast.parse(text)):
            src = ast.unparse(ann)
            total += 1
            names = {n.id for n in ast.walk(ann) if isinstance(n, ast.Name)}
            names |= {n.attr for n in ast.walk(ann) if isinstance(n, ast.Attribute)}
            if "Any" in names or "Any" in src.split("'"):
                any_ += 1
                if "dict[str, Any]" in src.replace("'", ""):
                    dict_any += 1
    return {"annotations": total, "mention_any": any_, "dict_str_any": dict_any}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("packages", nargs="*", default=["app"])
    ap.add_argument("--rev", default=None, help="a git revision (default: the work tree)")
    args = ap.parse_args()
    for package in args.packages:
        c = count(package, args.rev)
        share = c["mention_any"] / c["annotations"] if c["annotations"] else 0.0
        print(f"{package}{'@' + args.rev if args.rev else ''}: {c['annotations']} annotations, "
              f"{c['mention_any']} mention Any ({share:.1%}), {c['dict_str_any']} dict[str, Any]")


if __name__ == "__main__":
    main()
