"""`astaa-deft examples DIR`: the bundled spec, test cases and dictionary copied to a folder of one's own.

The README's examples name ``specs/demo_av.yaml`` and ``policies/examples/…``:
inside a clone they are there; anywhere else, ``astaa-deft examples DIR`` puts
them in DIR so the same lines work from it. Files already there are kept.
"""

from __future__ import annotations

import argparse
import shutil
from pathlib import Path
from typing import TYPE_CHECKING

from astaa_deft.cli.commands.console import say
from astaa_deft.demo.bundled import example_files
from astaa_deft.io.output_place import Place, ready_dir, writing

if TYPE_CHECKING:
    from astaa_deft.cli.arguments import SubParsers


def add_parser(subparsers: SubParsers) -> None:
    """Declare the `examples` command."""
    ex = subparsers.add_parser("examples", help="copy the bundled spec, test cases and dictionary to a folder, so "
                                                "the README's examples run from it",
                               epilog="example:\n  astaa-deft examples my-stack && cd my-stack\n"
                                      "  astaa-deft proxy --spec specs/demo_av.yaml --policy "
                                      "policies/examples/demo_nan_speed_limit.xml --record run.mcap")
    ex.add_argument("out", type=Path, help="the folder to copy them to (created if missing)")
    ex.add_argument("--overwrite", action="store_true",
                    help="replace files of the same name already there (default: keep them)")
    ex.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """The parsed `examples` arguments to :func:`copy_examples`."""
    return copy_examples(args.out, overwrite=args.overwrite)


def copy_examples(out: Path, *, overwrite: bool = False) -> int:
    """Copy every bundled example file under ``out``; print what was copied and kept. Always 0 (OutputError when
    ``out`` cannot be written)."""
    place = Place(out, "the examples folder")
    ready_dir(place)
    copied, kept = [], []
    with writing(place):
        for source, relative in example_files():
            target = out / relative
            if target.exists() and not overwrite:
                kept.append(relative)
                continue
            target.parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(source, target)
            copied.append(relative)
    say(f"{len(copied)} file(s) copied to {out}/: " + ", ".join(sorted({str(p.parts[0]) + '/' for p in copied}))
        if copied else f"nothing copied to {out}/")
    if kept:
        say(f"{len(kept)} file(s) already there kept (--overwrite replaces them): "
            + ", ".join(str(p) for p in kept[:5]) + (" …" if len(kept) > 5 else ""))
    say(f"try: cd {out} && astaa-deft spec check specs/demo_av.yaml")
    return 0
