"""`astaa-deft generate --spec SUT.yaml --count N --seed S -o DIR`: write N test cases.

The work is :func:`astaa_deft.engine.intercept.generate.generate_to_directory`; this prints what it wrote.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

from astaa_deft.cli.arguments import CASES, SEED, WINDOW_SECONDS, bounded

if TYPE_CHECKING:
    from astaa_deft.cli.arguments import SubParsers
    from astaa_deft.engine.intercept.generate import GenerateOptions


def add_parser(subparsers: SubParsers) -> None:
    """Declare the `generate` command."""
    gen = subparsers.add_parser("generate", help="write ASTAA test cases drawn from a spec and the dictionary",
                                 epilog="example:\n  astaa-deft generate --spec specs/demo_av.yaml --count 20 "
                                        "--seed 1 -o cases/\n"
                                        "  astaa-deft proxy --spec specs/demo_av.yaml --policy cases/tc-000001.xml "
                                        "--record run.mcap")
    gen.add_argument("--spec", type=Path, required=True, help="the SUT spec (YAML) whose channels and fields "
                                                                  "the cases target")
    bounded(gen, "--count", CASES, required=True, help="test cases to write")
    bounded(gen, "--seed", SEED, required=True, help="the seed of the draw (the same seed, the same cases)")
    gen.add_argument("-o", "--out", type=Path, required=True, help="the directory the test case files go to")
    bounded(gen, "--duration", WINDOW_SECONDS, default=30.0, help="windows fall inside this many seconds")
    gen.add_argument("--include-brittle", action="store_true", help="also target timestamps, sequence numbers… "
                     "(default: the spec's brittle fields are left alone)")
    gen.add_argument("--dictionary", type=Path, action="append", default=[],
                     help="an exceptional-value dictionary on top of the default one (repeatable; default: "
                          "the bundled one only)")
    gen.add_argument("--family", action="append", default=None, metavar="NAME",
                     help="draw only these fault families (repeat the option; default: every family but the "
                          "campaign's message faults; docs/policies.md lists them)")
    gen.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """The parsed `generate` arguments to :func:`generate`."""
    from astaa_deft.engine.intercept.generate import GenerateOptions

    return generate(args.spec, args.out, GenerateOptions(
        count=args.count, seed=args.seed, duration=args.duration, include_brittle=args.include_brittle,
        dictionaries=tuple(args.dictionary), families=args.family))


def generate(spec_path: Path, out_dir: Path, options: GenerateOptions) -> int:
    """Write the test cases ``options`` asks for into ``out_dir`` and print their shapes: 0.

    Raises InputError for a spec or dictionary that does not load, a bad count or duration, an unknown
    family, or an output directory that holds test cases already; OutputError when ``out_dir`` cannot be
    written.
    """
    from astaa_deft.engine.intercept.faults import FAMILIES
    from astaa_deft.engine.intercept.generate import generate_to_directory
    from astaa_deft.engine.spec.loader import load_spec

    report = generate_to_directory(load_spec(spec_path), out_dir, options)
    shapes = report.shapes
    semantic = ", ".join(f"{shapes[f.name]} {f.name}" for f in FAMILIES.values() if f.semantic and shapes[f.name])
    print(f"wrote {report.count} test cases to {out_dir} (seed {options.seed}): {shapes['single']} one field of one "
          f"message, {shapes['multi_field']} several fields of one message, {shapes['repeated']} repeated, "
          f"{shapes['sustained']} sustained, {shapes['stamp']} stamp or sequence faults"
          + (f"; plausible but wrong: {semantic}" if semantic else ""))
    return 0
