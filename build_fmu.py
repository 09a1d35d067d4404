"""Build every FMU of the package into one folder.

    python build_fmu.py                 # -> build/fmus/{pounding,building,ground_motion}.fmu
    python build_fmu.py --out DIR       # another folder
    python build_fmu.py --force         # rebuild even if the sources did not change

Each FMU is a pythonfmu co-simulation slave; what is built and how lives in
:mod:`cosim.fmus` (the FMUs are declared once, as data, in ``cosim.fmus.FMUS``).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from cosim.fmus import FMU_NAMES, FMUS, build_all, fmu_folder  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=fmu_folder(), help="output folder (default: build/fmus)")
    parser.add_argument("--force", action="store_true", help="rebuild even if sources are unchanged")
    parser.add_argument("names", nargs="*", help="FMUs to build (default: all)")
    args = parser.parse_args(argv)
    unknown = set(args.names) - set(FMU_NAMES)
    if unknown:
        parser.error(f"unknown FMU {sorted(unknown)}; known: {sorted(FMU_NAMES)}")
    print(f"Building FMUs into {args.out}")
    build_all(args.out, force=args.force, names=tuple(args.names) or None, quiet=False)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
