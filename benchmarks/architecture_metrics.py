"""The architecture's figures, measured on the package as it is; ``--check`` keeps them from rising.

    python benchmarks/architecture_metrics.py [--list] [--check | --write-baseline]

Prints: functions over 80 lines; functions with 8+ parameters and those of
them not keyword-only past the fourth; lines with ``.get("`` outside the
decoders of external formats — whole files (the spec reader, the YAML and
codec helpers, the bundled demo SUT) and the functions that read a user's
YAML node or XML element (a monitor kind's ``parse``, a fault action's
``from_xml``) — and of those how many sit inside a record type's own
decoder (``from_json``, ``from_*``, ``decode``: the one place a form read
from a file or a pipe becomes the type); ``Any`` in the public signatures of
the session, the campaign and the minimiser.

Package-wide (everything outside the bundled demo): ``Any`` in
public signatures (module-level functions and classes whose name does not
start with ``_``, their public methods and ``__init__``, and class
attributes annotated with ``Any``); functions taking more than four
positional parameters (``self``/``cls`` not counted); dataclasses whose
constructor takes more than four fields positionally (not ``kw_only``);
classes over 300 lines; calls of ``parse_testcase`` and ``to_xml`` in the
orchestration tier outside the journal and the case payload (where a test
case is stored or handed to a worker); and the import-linter contracts of
``pyproject.toml`` checked again with type-only imports (``if
TYPE_CHECKING:``) counted, as broken contracts and the imports that break
them. Also: modules over 700 lines, and comparisons of an invariant kind's
name as a string outside the kinds themselves (``engine/monitor/kinds/``):
a string constant naming a registered kind compared with a ``kind`` or
``invariant_kind`` attribute, or a set of such names bound to a ``*KIND*``
name — what a kind can be judged on belongs to the kind.

``--check`` compares the figures named in ``architecture_baseline.json``
(beside this script) and exits 1 naming each that rose above its committed
value (CI runs it); ``--write-baseline`` records the current figures there,
for a change that brings one down. Otherwise asserts nothing: the figures go
in the notes.
"""

from __future__ import annotations

import argparse
import ast
import json
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path

PACKAGE = Path(__file__).resolve().parent.parent / "astaa_deft"
# Decoders of formats a user writes (spec YAML, policies, dictionaries, invariants)
# and the system under test bundled as a demo: dict access is their job there.
EXTERNAL = ("demo/", "engine/spec/", "io/yamlsource.py", "io/codecs/", "engine/monitor/spec_reader.py",
            "engine/monitor/invariants.py", "engine/intercept/testcase/", "engine/intercept/dictionary/")
PUBLIC_SEAMS = ("engine/session/", "orchestration/campaign/", "analysis/minimise/")
BASELINE = Path(__file__).resolve().parent / "architecture_baseline.json"
KINDS_PACKAGE = "engine/monitor/kinds/"
LONG_MODULE = 700  # lines


def _kind_names(package: Path) -> frozenset[str]:
    """The registered invariant kinds: one module each under ``engine/monitor/kinds/`` (its file name)."""
    return frozenset(p.stem for p in (package / KINDS_PACKAGE).glob("*.py") if not p.stem.startswith("_"))


def _names_kind(node: ast.AST, kinds: frozenset[str]) -> bool:
    """A string constant naming a kind, or a literal collection holding one."""
    return any(isinstance(n, ast.Constant) and isinstance(n.value, str) and n.value in kinds for n in ast.walk(node))


def _reads_kind(node: ast.AST) -> bool:
    return isinstance(node, ast.Attribute) and node.attr in ("kind", "invariant_kind")


def _kind_string_checks(tree: ast.Module, kinds: frozenset[str]) -> list[int]:
    """Lines comparing an invariant kind by its name (``x.kind == "deadline"``, ``v.invariant_kind in (…)``) or
    binding a set of kind names to a ``*KIND*`` name."""
    lines = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Compare):
            operands = [node.left, *node.comparators]
            if any(_reads_kind(o) for o in operands) and any(_names_kind(o, kinds) for o in operands
                                                              if not _reads_kind(o)):
                lines.append(node.lineno)
        elif isinstance(node, (ast.Assign, ast.AnnAssign)):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            if node.value is not None and any(isinstance(t, ast.Name) and "KIND" in t.id for t in targets) and \
                    _names_kind(node.value, kinds):
                lines.append(node.lineno)
    return lines


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


def _signature_mentions_any(fn: ast.FunctionDef | ast.AsyncFunctionDef) -> bool:
    annotations = [a.annotation for a in [*fn.args.posonlyargs, *fn.args.args, *fn.args.kwonlyargs,
                                          fn.args.vararg, fn.args.kwarg] if a is not None]
    return any(_mentions_any(a) for a in [*annotations, fn.returns])


def _public_anys(rel: str, tree: ast.Module) -> list[str]:
    found = []
    for name, fn in _public_functions(tree):
        if isinstance(fn, ast.AnnAssign):
            found.append(f"{rel} {name}")
        elif _signature_mentions_any(fn):
            found.append(f"{rel}:{fn.lineno} {name}")
    return found


def _is_dataclass(cls: ast.ClassDef) -> tuple[bool, bool]:
    """(a dataclass, declared ``kw_only=True``)."""
    for deco in cls.decorator_list:
        target = deco.func if isinstance(deco, ast.Call) else deco
        name = target.id if isinstance(target, ast.Name) else target.attr if isinstance(target, ast.Attribute) else ""
        if name == "dataclass":
            kw_only = isinstance(deco, ast.Call) and any(
                k.arg == "kw_only" and isinstance(k.value, ast.Constant) and k.value.value is True
                for k in deco.keywords)
            return True, kw_only
    return False, False


def _positional_fields(cls: ast.ClassDef) -> int:
    """Fields a dataclass's constructor takes positionally (up to a ``_: KW_ONLY`` marker; ClassVars not fields)."""
    count = 0
    for item in cls.body:
        if isinstance(item, ast.AnnAssign) and isinstance(item.target, ast.Name):
            annotation = ast.unparse(item.annotation)
            if "KW_ONLY" in annotation:
                break
            if "ClassVar" in annotation:
                continue
            if isinstance(item.value, ast.Call) and ast.unparse(item.value.func).endswith("field") and any(
                    k.arg in ("init", "kw_only") for k in item.value.keywords):
                continue
            count += 1
    return count


def _calls(tree: ast.Module, names: tuple[str, ...]) -> list[tuple[int, str]]:
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Call):
            func = node.func
            name = func.id if isinstance(func, ast.Name) else func.attr if isinstance(func, ast.Attribute) else ""
            if name in names:
                out.append((node.lineno, name))
    return out


def _contracts_with_type_checking(package: Path) -> list[str]:
    """The import-linter contracts of pyproject.toml, run with type-only imports counted: what breaks."""
    pyproject = package.parent / "pyproject.toml"
    text = pyproject.read_text()
    section = text[text.index("[tool.importlinter]"):]
    section = re.sub(r"exclude_type_checking_imports\s*=\s*true", "exclude_type_checking_imports = false", section)
    if "exclude_type_checking_imports" not in section:
        section = section.replace("[tool.importlinter]\n",
                                  "[tool.importlinter]\nexclude_type_checking_imports = false\n", 1)
    with tempfile.TemporaryDirectory() as tmp:
        config = Path(tmp) / "importlinter.toml"
        config.write_text(section)
        env = {**os.environ, "PYTHONPATH": str(package.parent), "COLUMNS": "1000"}  # one chain a line
        lint = Path(sys.executable).parent / "lint-imports"
        done = subprocess.run([str(lint), "--config", str(config), "--no-cache"], cwd=package.parent, env=env,
                              capture_output=True, text=True, check=False)
    broken = [line.strip() for line in done.stdout.splitlines() if line.rstrip().endswith("BROKEN")]
    imports = [line.strip() for line in done.stdout.splitlines()  # direct imports: "- a -> b (l.N)"
               if re.match(r"^- astaa_deft\.\S+ -> astaa_deft\.\S+ \(l\.\d+\)$", line.strip())]
    return [f"contract {b}" for b in broken] + [f"  import {i.lstrip('- ')}" for i in imports]


def main() -> None:
    global PACKAGE
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--list", action="store_true", help="name every place, not only the counts")
    parser.add_argument("--package", type=Path, default=PACKAGE,
                        help="the astaa_deft folder to measure (default: this checkout's), e.g. another worktree's")
    parser.add_argument("--check", action="store_true",
                        help=f"exit 1 if a figure rose above {BASELINE.name}")
    parser.add_argument("--write-baseline", action="store_true", help=f"record the figures in {BASELINE.name}")
    args = parser.parse_args()
    PACKAGE = args.package.resolve()
    kinds = _kind_names(PACKAGE)
    long_modules: list[str] = []
    kind_strings: list[str] = []
    package_anys, positional_over_four, positional_records, long_classes, xml_calls = [], [], [], [], []
    long_functions, many_params, positional_past_four, gets, anys = [], [], [], [], []
    in_decoders: list[str] = []
    for path in sorted(PACKAGE.rglob("*.py")):
        rel = path.relative_to(PACKAGE).as_posix()
        text = path.read_text()
        tree = ast.parse(text)
        if not rel.startswith("demo/"):
            lines = text.count("\n")
            if lines > LONG_MODULE:
                long_modules.append(f"{rel} ({lines} lines)")
            if not rel.startswith(KINDS_PACKAGE):
                kind_strings.extend(f"{rel}:{line}" for line in _kind_string_checks(tree, kinds))
            for node in ast.walk(tree):
                if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                    where = f"{rel}:{node.lineno} {node.name}"
                    length = node.end_lineno - node.lineno + 1
                    if length > 80:
                        long_functions.append(f"{where} ({length} lines)")
                    count, positional = _params(node)
                    if positional > 4:
                        positional_over_four.append(f"{where} ({positional} positional)")
                    if count >= 8:
                        many_params.append(f"{where} ({count} parameters)")
                        if positional > 4:
                            positional_past_four.append(f"{where} ({positional} positional)")
            for node in ast.walk(tree):
                if isinstance(node, ast.ClassDef):
                    length = node.end_lineno - node.lineno + 1
                    if length > 300:
                        long_classes.append(f"{rel}:{node.lineno} {node.name} ({length} lines)")
                    dataclass, kw_only = _is_dataclass(node)
                    if dataclass and not kw_only and _positional_fields(node) > 4:
                        positional_records.append(f"{rel}:{node.lineno} {node.name} "
                                                  f"({_positional_fields(node)} positional fields)")
            package_anys.extend(_public_anys(rel, tree))
        if rel.startswith("orchestration/") and rel not in ("orchestration/journal/journal.py",
                                                             "orchestration/journal/model.py",
                                                             "orchestration/campaign/payload.py"):
            xml_calls.extend(f"{rel}:{line} {name}" for line, name in _calls(tree, ("parse_testcase", "to_xml")))
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
            anys.extend(_public_anys(rel, tree))
    layer_breaks = _contracts_with_type_checking(PACKAGE)
    figures = (("modules over 700 lines", long_modules),
               ("functions over 80 lines", long_functions),
               ("functions with 8+ parameters", many_params),
               ("  of them positional past the fourth", positional_past_four),
               ('lines with .get(" outside external-format decoders', gets),
               ("  of them in a record type's own decoder (from_json, from_*, decode)", in_decoders),
               ("Any in public signatures of session, campaign, minimiser", anys),
               ("Any in public signatures, package-wide (demo excepted)", package_anys),
               ("functions with more than 4 positional parameters", positional_over_four),
               ("dataclasses with more than 4 positional fields", positional_records),
               ("classes over 300 lines", long_classes),
               ("parse_testcase/to_xml calls in orchestration outside journal and payload", xml_calls),
               ("layer contracts broken with TYPE_CHECKING imports counted",
                [b for b in layer_breaks if b.startswith("contract")]),
               ("  the imports that break them", [b for b in layer_breaks if not b.startswith("contract")]),
               ("invariant kinds compared by name outside the kinds", kind_strings))
    for title, items in figures:
        print(f"{title}: {len(items)}")
        if args.list:
            for item in items:
                print(f"    {item}")
    counts = {title.strip(): len(items) for title, items in figures}
    if args.write_baseline:
        BASELINE.write_text(json.dumps(counts, indent=2) + "\n")
        print(f"wrote {BASELINE}")
    if args.check:
        baseline = json.loads(BASELINE.read_text())
        risen = [f"{title}: {counts[title]} > {limit}" for title, limit in baseline.items()
                 if counts.get(title, 0) > limit]
        for line in risen:
            print(f"rose above {BASELINE.name}: {line}", file=sys.stderr)
        if risen:
            sys.exit(1)


if __name__ == "__main__":
    main()
