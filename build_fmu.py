"""Build every FMU of the package into one folder.

    python build_fmu.py                 # -> build/fmus/{pounding,building,ground_motion}.fmu
    python build_fmu.py --out DIR       # another folder
    python build_fmu.py --force         # rebuild even if the sources did not change

Each FMU is a pythonfmu co-simulation slave.  The FMUs to build are declared
once, as data, in ``FMUS``.  A build is skipped when the FMU exists and was
built from the same sources (a hash of ``fmu_src`` stored next to it), so
tests and scripts can call :func:`build_all` freely.
"""
from __future__ import annotations

import argparse
import hashlib
import sys
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parent
SOURCE = ROOT / "fmu_src"
DEFAULT_OUT = ROOT / "build" / "fmus"


@dataclass(frozen=True)
class FmuSpec:
    name: str          # file name without .fmu, and the instance name scenes use by default
    script: str        # slave script inside fmu_src/ (unique module name per FMU)
    summary: str


FMUS = (
    FmuSpec("pounding", "pounding_slave.py", "contact element: spring + dashpot impact laws"),
    FmuSpec("building", "building_slave.py", "shear building, 1 to 20 storeys, linear or yielding storeys"),
    FmuSpec("ground_motion", "ground_motion_slave.py", "plays a recorded ground acceleration"),
)

# Capabilities every FMU really supports (declared once).
CAPABILITIES = dict(canGetAndSetFMUstate=True, canHandleVariableCommunicationStepSize=True)


def source_hash() -> str:
    digest = hashlib.sha256()
    for path in sorted(SOURCE.rglob("*")):
        if path.is_file() and "__pycache__" not in path.parts:
            digest.update(str(path.relative_to(SOURCE)).encode())
            digest.update(path.read_bytes())
    return digest.hexdigest()


def build_one(spec: FmuSpec, out: Path, force: bool = False, digest: str | None = None) -> Path:
    """Build one FMU into ``out`` unless an up-to-date one is there."""
    from pythonfmu.builder import FmuBuilder

    digest = digest or source_hash()
    target = out / f"{spec.name}.fmu"
    stamp = out / f".{spec.name}.sha256"
    if not force and target.exists() and stamp.exists() and stamp.read_text() == digest:
        return target
    out.mkdir(parents=True, exist_ok=True)
    if str(ROOT) not in sys.path:
        sys.path.insert(0, str(ROOT))  # the slave scripts import the fmu_src package
    partial = out / f".{spec.name}.partial.fmu"
    FmuBuilder.build_FMU(SOURCE / spec.script, dest=partial, project_files=[SOURCE], **CAPABILITIES)
    partial.replace(target)  # never leave a half-written FMU under its real name
    stamp.write_text(digest)
    return target


def build_all(out: Path | str = DEFAULT_OUT, force: bool = False, names: tuple[str, ...] | None = None,
              quiet: bool = True) -> dict[str, Path]:
    """Build the FMUs (all, or those in ``names``) and return their paths by name."""
    out = Path(out)
    digest = source_hash()
    built = {}
    for spec in FMUS:
        if names is not None and spec.name not in names:
            continue
        built[spec.name] = build_one(spec, out, force=force, digest=digest)
        if not quiet:
            print(f"  {spec.name + '.fmu':<20} {spec.summary}  -> {built[spec.name]}")
    return built


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT, help="output folder (default: build/fmus)")
    parser.add_argument("--force", action="store_true", help="rebuild even if sources are unchanged")
    parser.add_argument("names", nargs="*", help="FMUs to build (default: all)")
    args = parser.parse_args(argv)
    known = {spec.name for spec in FMUS}
    unknown = set(args.names) - known
    if unknown:
        parser.error(f"unknown FMU {sorted(unknown)}; known: {sorted(known)}")
    print(f"Building FMUs into {args.out}")
    build_all(args.out, force=args.force, names=tuple(args.names) or None, quiet=False)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
