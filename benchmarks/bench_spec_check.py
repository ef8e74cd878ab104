"""How the time to load (check) a spec grows with its number of channels.

    python benchmarks/bench_spec_check.py [--channels 2500,5000,10000,20000]

Writes one spec per size (two modules, N channels of one small type, flow
style as a generator would write them), loads each with ``load_spec`` as
``astaa-deft spec check`` does, and prints the seconds, the microseconds per
channel and the ratio of the largest to the smallest size's time against
the ratio of their sizes (equal ratios: linear; the square of it: quadratic).
Asserts nothing.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

from astaa_deft.engine.spec.loader import load_spec


def spec_text(channels: int) -> str:
    rows = "".join(f"  - {{name: c{i}, key: big/c{i}, producer: a, consumers: [b], type: Sample}}\n"
                   for i in range(channels))
    return ("name: big\nmodules: [{name: a, command: 'true'}, {name: b, command: 'true'}]\n"
            f"channels:\n{rows}types:\n  Sample: {{seq: uint64, value: float64}}\n")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--channels", default="2500,5000,10000,20000", help="sizes, comma-separated")
    sizes = sorted(int(n) for n in parser.parse_args().channels.split(","))
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


if __name__ == "__main__":
    main()
