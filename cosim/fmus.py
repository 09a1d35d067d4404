"""The package's FMUs as data, and building them (one source of truth for every FMU name).

:data:`FMUS` lists the three FMUs once: the build, the master's catalog, the scene loader and
the SSP bridge all read it.  :func:`build_all` turns the physics package ``fmu_src`` into the
FMU files:

* **One uniquely named package per FMU.**  Each FMU ships the modules its slave needs (found by
  following the slave module's relative imports) copied into a package named
  ``pounding_cosim_<fmu>_<hash>`` (``<hash>``: 8 hex digits of SHA-256 over those sources), and
  a generated slave script that imports it.  All pythonfmu FMUs of a process share one Python
  interpreter (one ``sys.modules``): with one shared name, the first FMU loaded decided what
  every later one imported, and after ``fmpy.simulate_fmu`` deleted the first FMU's folder the
  next FMU failed with ``No module named 'fmu_src.shear_building'``.  Two versions of the same
  FMU in one process also get different names.
* **Declared host requirements.**  The FMU's Python code needs numpy and scipy from the host's
  Python (:data:`fmu_src.fmi_slave.HOST_REQUIREMENTS`): ``resources/requirements.txt`` (where
  ``pythonfmu deploy`` looks for it) and the modelDescription's description say so, and the
  generated script turns a missing package into a message that names it (:func:`slave_script`).
* **Up to date, never half-written.**  A build is skipped when the FMU exists and was built from
  the same sources (a digest stored next to it); a new FMU is written under a temporary name
  and renamed.

Where FMUs live (:func:`default_fmu_dir`): in a source checkout ``build/fmus``; in an installed
package a per-user cache, ``$XDG_CACHE_HOME/pounding-cosim/fmus/<version>-<hash>/`` (default
``~/.cache/...``): an installed package never writes into site-packages.
"""
from __future__ import annotations

import ast
import functools
import hashlib
import os
import shutil
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

#: the physics package whose modules every FMU ships (under its own name)
SOURCE = Path(__file__).resolve().parents[1] / "fmu_src"
#: a source checkout: the folder holding ``pyproject.toml``, ``cosim/`` and ``fmu_src/``
CHECKOUT = Path(__file__).resolve().parents[1]
PACKAGE_PREFIX = "pounding_cosim"

GROUND, BUILDING, POUNDING = "ground_motion", "building", "pounding"


@dataclass(frozen=True)
class FmuSpec:
    """One FMU of the package.

    ``name``: the file name without ``.fmu`` (and the FMU kind scenes refer to); ``module``:
    the slave module inside ``fmu_src``; ``class_name``: its slave class; ``role``: what the
    master does with its instances (``"ground"``, ``"contact"``, ``"building"``); ``summary``:
    one line for listings; ``data``: folders of ``fmu_src`` the FMU ships besides modules;
    ``long_quiet_steps``: one step over an interval in which nothing happens to the FMU gives
    what many shorter steps over it give (the adaptive master then takes long steps there,
    :mod:`cosim.master.coupling.adaptive`).
    """

    name: str
    module: str
    class_name: str
    role: str
    summary: str
    data: tuple[str, ...] = ()
    long_quiet_steps: bool = True


FMUS = (
    # long_quiet_steps=False: a resolved contact (resolve_impacts = true) predicts the bodies'
    # flight over a step from the structures' motion it learnt over its previous step; over a
    # step many times longer that prediction can cross the gap where the bodies never do (a
    # spurious impact: tests/test_dormancy.py shows one), so the master gives it no undeclared
    # long step: it takes long steps only while such contacts sleep, and their catch-up declares
    # the skipped interval open (input gap_open: no prediction over it; cosim/master/dormancy.py;
    # plain contacts take any step)
    FmuSpec(POUNDING, "pounding_slave", "Pounding", "contact", "contact element: spring + dashpot impact laws",
            long_quiet_steps=False),
    FmuSpec(BUILDING, "building_slave", "Building", "building", "shear building, 1 to 20 storeys, linear or yielding storeys"),
    FmuSpec(GROUND, "ground_motion_slave", "GroundMotion", "ground", "plays a recorded ground acceleration",
            data=("records",)),
)
FMU_NAMES = tuple(spec.name for spec in FMUS)

#: capabilities every FMU really supports (declared once)
CAPABILITIES = dict(canGetAndSetFMUstate=True, canHandleVariableCommunicationStepSize=True)


def fmu_spec(name: str) -> FmuSpec:
    """The spec of FMU ``name`` (ValueError naming the known ones otherwise)."""
    for spec in FMUS:
        if spec.name == name:
            return spec
    raise ValueError(f"unknown FMU {name!r}; known: {', '.join(FMU_NAMES)}")


# -- what goes into an FMU ---------------------------------------------------------------------------
def file_sha256(path: str | Path) -> str:
    """SHA-256 (hex) of a file's bytes: what summaries and studies record of the FMUs and records
    a run used.  Kept per (path, size, modification time): a study hashes each FMU once."""
    path = Path(path)
    stat = path.stat()
    return _sha256(str(path.absolute()), stat.st_size, stat.st_mtime_ns)


@functools.lru_cache(maxsize=64)
def _sha256(path: str, size: int, mtime_ns: int) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def fmu_hashes(fmu_dir: str | Path, names: Sequence[str] = FMU_NAMES) -> dict[str, str]:
    """``{name: SHA-256 of <fmu_dir>/<name>.fmu}``."""
    return {n: file_sha256(Path(fmu_dir) / f"{n}.fmu") for n in names}


def _relative_imports(path: Path) -> list[str]:
    """Modules of the same package that ``path`` imports (``from .x import ...``)."""
    stat = path.stat()
    return list(_parsed_imports(str(path), stat.st_mtime_ns, stat.st_size))


@functools.lru_cache(maxsize=256)
def _parsed_imports(path: str, mtime_ns: int, size: int) -> tuple[str, ...]:
    # Every run checks that its FMUs are up to date, which walks the sources' imports: parsing a
    # file once per version (keyed by its modification time and size) saves ~0.2 s per run.
    names = []
    for node in ast.walk(ast.parse(Path(path).read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom) and node.level == 1:
            if node.module:
                names.append(node.module.split(".")[0])
            else:
                names.extend(alias.name for alias in node.names)
    return tuple(names)


def fmu_modules(spec: FmuSpec, source: Path = SOURCE) -> list[str]:
    """The modules of ``source`` the FMU needs: its slave module and everything it imports
    relatively, transitively (sorted)."""
    seen, todo = set(), [spec.module]
    while todo:
        module = todo.pop()
        if module in seen:
            continue
        path = source / f"{module}.py"
        if not path.is_file():
            raise FileNotFoundError(f"{spec.name}.fmu needs {path}, which does not exist")
        seen.add(module)
        todo.extend(_relative_imports(path))
    return sorted(seen)


def _files(spec: FmuSpec, source: Path) -> list[Path]:
    files = [source / f"{m}.py" for m in fmu_modules(spec, source)]
    for folder in spec.data:
        files += sorted(p for p in (source / folder).rglob("*") if p.is_file() and "__pycache__" not in p.parts)
    return files


def source_digest(spec: FmuSpec, source: Path = SOURCE) -> str:
    """SHA-256 over what the FMU ships and how it is built (sources, data, this module, version)."""
    from fmu_src.fmi_slave import HOST_REQUIREMENTS

    digest = hashlib.sha256()
    for path in _files(spec, source):
        digest.update(str(path.relative_to(source)).encode())
        digest.update(path.read_bytes())
    digest.update(Path(__file__).read_bytes())
    digest.update(" ".join(HOST_REQUIREMENTS).encode())
    digest.update(f"{sys.version_info[0]}.{sys.version_info[1]}".encode())
    return digest.hexdigest()


def package_name(spec: FmuSpec, digest: str) -> str:
    """``pounding_cosim_<fmu>_<8 hex digits>``: the name the FMU's Python code is imported under."""
    return f"{PACKAGE_PREFIX}_{spec.name}_{digest[:8]}"


def slave_script(spec: FmuSpec, package: str) -> str:
    """The slave script pythonfmu loads: imports the FMU's own package, names a missing package.

    pythonfmu 0.7 reports any exception raised while the script is imported as
    ``fmi2Instantiate`` failing, and logs its text (with status fmi2Fatal) only when the host
    instantiated with ``loggingOn = fmi2True``.  So the message names the missing package and
    the remedy, and is also written to the process's standard error, which a host shows even
    when FMI logging is off.
    """
    from fmu_src.fmi_slave import HOST_REQUIREMENTS

    needs = " and ".join(r.split(">")[0].split("=")[0] for r in HOST_REQUIREMENTS)
    return f'''"""{spec.name}.fmu slave script, generated by cosim.fmus at build time (do not edit).

The FMU's Python code is the package ``{package}`` next to this file: the modules of
``fmu_src`` this FMU needs, under a name no other FMU uses.
"""
import ctypes as _ctypes

try:
    from {package}.{spec.module} import {spec.class_name} as _Slave
except ImportError as exc:   # a host Python without the FMU's requirements
    _message = ("{spec.name}.fmu cannot start: its Python code needs {needs} in the host's Python "
                f"(missing: {{exc.name or exc}}); install them with "
                "'pip install -r resources/requirements.txt' of the FMU "
                "(or 'pythonfmu deploy -f {spec.name}.fmu')")
    import sys as _sys
    print(f"error: {{_message}}", file=_sys.stderr, flush=True)
    raise ImportError(_message, name=exc.name) from None


class {spec.class_name}(_Slave):
    """The FMU's slave class ({package}.{spec.module}.{spec.class_name})."""

    def __init__(self, **kwargs):
        # pythonfmu 0.7's loader (PySlaveInstance.cpp, findClass) runs this script again in this
        # module's namespace at every fmi2Instantiate and then releases a reference to the
        # namespace that it never took (Py_DECREF of the borrowed PyModule_GetDict).  In 0.7.0
        # that is offset only because it also leaks the class the rerun defines (with its
        # methods, which reference the namespace): a script that merely imported the class
        # had its namespace freed at the first instance, and the second instance of the FMU in
        # a process failed ("module has no attribute").  So the class is defined here, with
        # this method, and each instance also gives the reference back itself, so that a
        # pythonfmu that stops leaking still finds the namespace alive (one reference per
        # instance more than needed otherwise: harmless, the module lives as long as the process).
        _ctypes.pythonapi.Py_IncRef(_ctypes.py_object(globals()))
        super().__init__(**kwargs)
'''


# -- building ------------------------------------------------------------------------------------------
def up_to_date(spec: FmuSpec, out: Path | str, source: Path = SOURCE) -> bool:
    """True when ``out`` holds ``spec``'s FMU built from the current sources (its stamp matches)."""
    target, stamp = Path(out) / f"{spec.name}.fmu", Path(out) / f".{spec.name}.sha256"
    return target.exists() and stamp.exists() and stamp.read_text() == source_digest(spec, source)


def build_one(spec: FmuSpec, out: Path | str, force: bool = False, source: Path = SOURCE) -> Path:
    """Build one FMU into ``out`` unless an up-to-date one is there; returns its path."""
    from fmu_src.fmi_slave import HOST_REQUIREMENTS
    from pythonfmu.builder import FmuBuilder

    out = Path(out)
    digest = source_digest(spec, source)
    target = out / f"{spec.name}.fmu"
    stamp = out / f".{spec.name}.sha256"
    if not force and up_to_date(spec, out, source):
        return target
    out.mkdir(parents=True, exist_ok=True)
    package = package_name(spec, digest)
    with tempfile.TemporaryDirectory(prefix=f"build_{spec.name}_") as tmp:
        stage = Path(tmp)
        pkg = stage / package
        pkg.mkdir()
        (pkg / "__init__.py").write_text(f'"""{spec.name}.fmu: {spec.summary} (copy of fmu_src, '
                                         f'built by cosim.fmus)."""\n')
        for module in fmu_modules(spec, source):
            shutil.copy2(source / f"{module}.py", pkg / f"{module}.py")
        for folder in spec.data:
            shutil.copytree(source / folder, pkg / folder, ignore=shutil.ignore_patterns("__pycache__"))
        requirements = stage / "requirements.txt"
        requirements.write_text("".join(f"{r}\n" for r in HOST_REQUIREMENTS))
        script = stage / f"{package}_slave.py"
        script.write_text(slave_script(spec, package))
        partial = out / f".{spec.name}.partial.fmu"
        path_before = list(sys.path)
        try:
            FmuBuilder.build_FMU(script, dest=partial, project_files=[pkg, requirements], **CAPABILITIES)
        finally:
            # pythonfmu imported the staged package (sys.path, sys.modules); forget it, so that
            # this process imports the FMU's code from the FMU when it loads it
            sys.path[:] = path_before
            for name in [m for m in sys.modules if m == package or m.startswith(package + ".")
                         or m == script.stem]:
                del sys.modules[name]
    partial.replace(target)  # never leave a half-written FMU under its real name
    stamp.write_text(digest)
    return target


def build_all(out: Path | str | None = None, force: bool = False, names: Sequence[str] | None = None,
              quiet: bool = True) -> dict[str, Path]:
    """Build the FMUs (all, or those in ``names``) into ``out`` (default :func:`default_fmu_dir`'s
    folder) and return their paths by name."""
    if names is not None:
        for name in names:
            fmu_spec(name)
    out = Path(out) if out is not None else fmu_folder()
    built = {}
    for spec in FMUS:
        if names is not None and spec.name not in names:
            continue
        skipped = not force and up_to_date(spec, out)
        built[spec.name] = build_one(spec, out, force=force)
        if not quiet:
            state = "up to date, not rebuilt" if skipped else "built"
            print(f"  {spec.name + '.fmu':<20} {spec.summary}  -> {built[spec.name]} ({state})")
    return built


# -- where FMUs live -----------------------------------------------------------------------------------
def source_checkout() -> bool:
    """True when the package runs from a source checkout (``pyproject.toml`` next to ``cosim/``),
    False when it is installed (site-packages)."""
    return (CHECKOUT / "pyproject.toml").is_file() and (CHECKOUT / "fmu_src").is_dir()


def cache_root() -> Path:
    """``$XDG_CACHE_HOME/pounding-cosim/fmus`` (default ``~/.cache/pounding-cosim/fmus``)."""
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "pounding-cosim" / "fmus"


def fmu_folder() -> Path:
    """The folder FMUs are built into by default: ``build/fmus`` in a source checkout, else
    ``<cache_root>/<version>-<hash of the sources>``."""
    if source_checkout():
        return CHECKOUT / "build" / "fmus"
    from . import __version__

    digest = hashlib.sha256("".join(source_digest(spec) for spec in FMUS).encode()).hexdigest()[:12]
    return cache_root() / f"{__version__}-{digest}"


def default_fmu_dir() -> Path:
    """The default FMU folder, built or refreshed from the current sources when needed."""
    folder = fmu_folder()
    build_all(folder)
    return folder
