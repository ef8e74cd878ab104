"""How the time to load (check) a spec grows with its number of channels.

    python benchmarks/bench_spec_check.py [--channels 2500,5000,10000,20000] [--choices 250,500,1000,100000]

Writes one spec per size (two modules, N channels of one small type, flow
style as a generator would write them), loads each with ``load_spec`` as
``astaa-deft spec check`` does, and prints the seconds, the microseconds per
channel and the ratio of the largest to the smallest size's time against
the ratio of their sizes (equal ratios: linear; the square of it: quadratic).
Then the same for one param with N ``choices`` (at most 1,000 load; more
are refused — the time to refuse is printed too). Asserts nothing.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

from astaa_deft.engine.spec.loader import load_spec
from astaa_deft.model.errors import InputError


def spec_text(channels: int) -> str:
    rows = "".join(f"  - {{name: c{i}, key: big/c{i}, producer: a, consumers: [b], type: Sample}}\n"
                   for i in range(channels))
    return ("name: big\nmodules: [{name: a, command: 'true'}, {name: b, command: 'true'}]\n"
            f"channels:\n{rows}types:\n  Sample: {{seq: uint64, value: float64}}\n")


def choices_text(choices: int) -> str:
    listed = ", ".join(f"s{i}" for i in range(choices))
    return (spec_text(1) + f"params:\n  scenario: {{choices: [{listed}]}}\n")


def bench_choices(sizes: list[int]) -> None:
    seconds: dict[int, float] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for size in sizes:
            path = Path(tmp) / f"choices-{size}.yaml"
            path.write_text(choices_text(size))
            start = time.perf_counter()
            try:
                load_spec(path)
                what = "loaded"
            except InputError:
                what = "refused"
            seconds[size] = time.perf_counter() - start
            print(f"{size:>7} choices: {seconds[size]:7.3f} s  {seconds[size] / size * 1e6:7.1f} µs/choice ({what})")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--channels", default="2500,5000,10000,20000", help="sizes, comma-separated")
    parser.add_argument("--choices", default="250,500,1000,100000", help="choices of one param, comma-separated")
    args = parser.parse_args()
    sizes = sorted(int(n) for n in args.channels.split(","))
    seconds: dict[int, float] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for size in sizes:
            path = Path(tmp) / f"spec-{size}.yaml"
            path.write_text(spec_text(size))
            start = time.perf_counter()
            spec = load_spec(path)
            seconds[size] = time.perf_counter() - start
            assert len(spec.channels) == size
            print(f"{size:>7} channels: {seconds[size]:7.2f} s  {seconds[size] / size * 1e6:7.1f} µs/channel")
    small, large = sizes[0], sizes[-1]
    print(f"time ratio {large}/{small}: {seconds[large] / seconds[small]:.1f} "
          f"(size ratio {large / small:.1f}; quadratic would be {(large / small) ** 2:.1f})")
    bench_choices(sorted(int(n) for n in args.choices.split(",")))


if __name__ == "__main__":
    main()
