"""What a run was made with: package version, FMU files and record file, each with its SHA-256.

``summary.json`` keeps this as ``provenance`` beside the scene as it ran (``scene_as_run``,
:meth:`cosim.master.scene.Scene.as_run`) and the overrides, so that a result says what
produced it and a later run can tell whether it used the same FMUs and the same record.
"""
from __future__ import annotations

import platform
from pathlib import Path
from typing import TYPE_CHECKING, Any, Mapping

from fmu_src.ground_records import BUNDLED

from .. import __version__
from ..fmus import file_sha256

if TYPE_CHECKING:
    from .scene import Scene


def record_file(record: str) -> Path | None:
    """The file the ground FMU reads for the parameter ``record``: a bundled record's file in
    this package (the FMU ships the same bytes), or the path itself; None if there is none."""
    if record in BUNDLED:
        return BUNDLED[record].path
    path = Path(record)
    return path if path.is_file() else None


def provenance(scene: "Scene", fmus: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """``package_version``, ``python``, ``fmus`` (``{fmu: {file, sha256}}`` for the FMUs the scene
    instantiates, when ``fmus`` (a catalog) gives their paths) and ``record`` (``{parameter, file,
    sha256}``) of a run of ``scene``."""
    out: dict[str, Any] = dict(package_version=__version__, python=platform.python_version())
    used = sorted({spec.fmu for spec in scene.instances()})
    files = {}
    for name in used:
        path = getattr(fmus.get(name), "path", None) if fmus is not None else None
        if path is not None and Path(path).is_file():
            files[name] = dict(file=str(Path(path).absolute()), sha256=file_sha256(path))
    out["fmus"] = files
    if scene.ground is not None:
        record = str(scene.ground.value("record"))
        path = record_file(record)
        out["record"] = dict(parameter=record, file=str(path) if path else None,
                             sha256=file_sha256(path) if path else None)
    return out
