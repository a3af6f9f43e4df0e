"""Run one benchmark: ``python -m benchmarks NAME [ARGS...]``; no NAME lists them."""

from __future__ import annotations

import importlib
import pkgutil
import sys
from pathlib import Path


def _names() -> list[str]:
    here = Path(__file__).parent
    return sorted(
        i.name[len("bench_"):] for i in pkgutil.iter_modules([str(here)])
        if i.name.startswith("bench_")
    )


def main(argv: list[str]) -> int:
    names = _names()
    if not argv or argv[0] in {"-h", "--help"}:
        print("usage: python -m benchmarks NAME [ARGS...]\n\nbenchmarks: " + ", ".join(names))
        return 0 if argv else 2
    name = argv[0].removeprefix("bench_")
    if name not in names:
        print(f"unknown benchmark {argv[0]!r}; choose one of: {', '.join(names)}", file=sys.stderr)
        return 2
    mod = importlib.import_module(f"benchmarks.bench_{name}")
    return int(mod.main(argv[1:]) or 0)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
