"""The architecture's figures (issue 26's acceptance), measured on the package as it is.

    python benchmarks/architecture_metrics.py [--list]

Prints: functions over 80 lines; functions with 8+ parameters and those of
them not keyword-only past the fourth; lines with ``.get("`` outside the
decoders of external formats — whole files (the spec reader, the YAML and
codec helpers, the bundled demo SUT) and the functions that read a user's
YAML node or XML element (a monitor kind's ``parse``, a fault action's
``from_xml``) — and of those how many sit inside a record type's own
decoder (``from_json``, ``from_*``, ``decode``: the one place a form read
from a file or a pipe becomes the type); ``Any`` in the public signatures of
the session, the campaign and the minimiser. Asserts nothing: the figures go
in the notes.
"""

from __future__ import annotations

import argparse
import ast
import re
from pathlib import Path

PACKAGE = Path(__file__).resolve().parent.parent / "astaa_deft"
# Decoders of formats a user writes (spec YAML, policies, dictionaries, invariants)
# and the system under test bundled as a demo: dict access is their job there.
EXTERNAL = ("demo/", "engine/spec/", "io/yamlsource.py", "io/codecs/", "engine/monitor/spec_reader.py",
            "engine/monitor/invariants.py", "engine/intercept/testcase/", "engine/intercept/dictionary/")
PUBLIC_SEAMS = ("engine/session/", "orchestration/campaign/", "analysis/minimise/")


def _params(fn: ast.FunctionDef | ast.AsyncFunctionDef) -> tuple[int, int]:
    a = fn.args
    positional = [*a.posonlyargs, *a.args]
    if positional and positional[0].arg in ("self", "cls"):
        positional = positional[1:]
    return len(positional) + len(a.kwonlyargs), len(positional)


def _reads_user_format(fn: ast.FunctionDef | ast.AsyncFunctionDef) -> bool:
    """A function given a user's YAML node (and the invariant reader) or an XML element of a policy."""
    args = [*fn.args.posonlyargs, *fn.args.args, *fn.args.kwonlyargs]
    return any(a.annotation is not None and re.search(r"\b(Node|InvariantReader|_Element)\b", ast.unparse(a.annotation))
               for a in args)


def _mentions_any(node: ast.AST | None) -> bool:
    return node is not None and any(isinstance(n, ast.Name) and n.id == "Any" or
                                    isinstance(n, ast.Attribute) and n.attr == "Any" for n in ast.walk(node))


def _public_functions(tree: ast.Module):
    for node in tree.body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and not node.name.startswith("_"):
            yield node.name, node
        if isinstance(node, ast.ClassDef) and not node.name.startswith("_"):
            for item in node.body:
                if isinstance(item, (ast.FunctionDef, ast.AsyncFunctionDef)) and \
                        (not item.name.startswith("_") or item.name == "__init__"):
                    yield f"{node.name}.{item.name}", item
                if isinstance(item, ast.AnnAssign) and _mentions_any(item.annotation):
                    yield f"{node.name}.{ast.unparse(item.target)}", item


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--list", action="store_true", help="name every place, not only the counts")
    args = parser.parse_args()
    long_functions, many_params, positional_past_four, gets, anys = [], [], [], [], []
    in_decoders: list[str] = []
    for path in sorted(PACKAGE.rglob("*.py")):
        rel = path.relative_to(PACKAGE).as_posix()
        text = path.read_text()
        tree = ast.parse(text)
        if not rel.startswith("demo/"):
            for node in ast.walk(tree):
                if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                    where = f"{rel}:{node.lineno} {node.name}"
                    length = node.end_lineno - node.lineno + 1
                    if length > 80:
                        long_functions.append(f"{where} ({length} lines)")
                    count, positional = _params(node)
                    if count >= 8:
                        many_params.append(f"{where} ({count} parameters)")
                        if positional > 4:
                            positional_past_four.append(f"{where} ({positional} positional)")
        if not rel.startswith(EXTERNAL):
            functions = [node for node in ast.walk(tree) if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef))]
            decoders = [range(fn.lineno, fn.end_lineno + 1) for fn in functions
                        if fn.name.startswith("from_") or fn.name == "decode"]
            user_formats = [range(fn.lineno, fn.end_lineno + 1) for fn in functions if _reads_user_format(fn)]
            for n, line in enumerate(text.splitlines(), 1):
                if re.search(r'\.get\("', line) and not any(n in lines for lines in user_formats):
                    gets.append(f"{rel}:{n}")
                    if any(n in lines for lines in decoders):
                        in_decoders.append(f"{rel}:{n}")
        if rel.startswith(PUBLIC_SEAMS):
            for name, fn in _public_functions(tree):
                if isinstance(fn, ast.AnnAssign):
                    anys.append(f"{rel} {name}")
                    continue
                annotations = [a.annotation for a in [*fn.args.posonlyargs, *fn.args.args, *fn.args.kwonlyargs,
                                                      fn.args.vararg, fn.args.kwarg] if a is not None]
                if any(_mentions_any(a) for a in [*annotations, fn.returns]):
                    anys.append(f"{rel}:{fn.lineno} {name}")
    for title, items in (("functions over 80 lines", long_functions),
                         ("functions with 8+ parameters", many_params),
                         ("  of them positional past the fourth", positional_past_four),
                         ('lines with .get(" outside external-format decoders', gets),
                         ("  of them in a record type's own decoder (from_json, from_*, decode)", in_decoders),
                         ("Any in public signatures of session, campaign, minimiser", anys)):
        print(f"{title}: {len(items)}")
        if args.list:
            for item in items:
                print(f"    {item}")


if __name__ == "__main__":
    main()
