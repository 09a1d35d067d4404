"""Response spectra of records as files: a CSV table and a log-log plot, both with units.

The numbers come from :func:`fmu_src.response_spectrum.response_spectrum` (exact for the
piecewise-linear record, peaks between samples included).  This module only writes them; the
command that calls it (``pounding-cosim spectrum RECORD``) decides where.  Files are created
exclusively: an existing file is never replaced.
"""
from __future__ import annotations

import csv
import io
from pathlib import Path
from typing import Sequence

import numpy as np

from fmu_src.ground_records import G
from fmu_src.response_spectrum import ResponseSpectrum

#: Columns written per record, after ``period_s``: (suffix, unit label, value of a spectrum).
COLUMNS = (
    ("Sd_m", "m", lambda s: s.displacement),
    ("PSv_m_s", "m/s", lambda s: s.pseudo_velocity),
    ("PSa_m_s2", "m/s^2", lambda s: s.pseudo_acceleration),
    ("PSa_g", "g", lambda s: s.pseudo_acceleration / G),
    ("t_peak_s", "s", lambda s: s.peak_time),
)


def _check(spectra: Sequence[ResponseSpectrum]) -> list[ResponseSpectrum]:
    spectra = list(spectra)
    if not spectra:
        raise ValueError("no spectrum to write")
    first = spectra[0]
    for s in spectra[1:]:
        if not (np.array_equal(s.periods, first.periods) and s.damping == first.damping):
            raise ValueError(f"spectra {first.name!r} and {s.name!r} differ in periods or damping: "
                             f"one table needs one period grid and one damping ratio")
    names = [s.name or f"record{i + 1}" for i, s in enumerate(spectra)]
    if len(set(names)) != len(names):
        raise ValueError(f"two spectra have the same name: {names}")
    return spectra


def _names(spectra) -> list[str]:
    return [s.name or f"record{i + 1}" for i, s in enumerate(spectra)]


def spectrum_table(spectra: Sequence[ResponseSpectrum]) -> str:
    """CSV text: ``period_s`` and, per record, ``<name>.Sd_m``, ``.PSv_m_s``, ``.PSa_m_s2``,
    ``.PSa_g`` and ``.t_peak_s``; a first comment line states the damping ratio."""
    spectra = _check(spectra)
    names = _names(spectra)
    out = io.StringIO()
    out.write(f"# elastic response spectra, damping ratio {spectra[0].damping:g}; "
              f"pseudo-velocity PSv = w Sd, pseudo-acceleration PSa = w^2 Sd, g = {G} m/s^2\n")
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow(["period_s"] + [f"{n}.{suffix}" for n in names for suffix, _, _ in COLUMNS])
    columns = [spectra[0].periods] + [value(s) for s in spectra for _, _, value in COLUMNS]
    for row in zip(*columns):
        writer.writerow([f"{x:.10g}" for x in row])
    return out.getvalue()


def plot_spectra(spectra: Sequence[ResponseSpectrum]) -> bytes:
    """PNG bytes: displacement and pseudo-acceleration spectra against period, log-log axes."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    spectra = _check(spectra)
    fig, (ax_d, ax_a) = plt.subplots(1, 2, figsize=(11, 4.5))
    for name, s in zip(_names(spectra), spectra):
        ax_d.loglog(s.periods, s.displacement, lw=1.2, label=name)
        ax_a.loglog(s.periods, s.pseudo_acceleration / G, lw=1.2, label=f"{name} (PGA {s.pga / G:.3g} g)")
    zeta = spectra[0].damping
    ax_d.set_ylabel("spectral displacement Sd [m]")
    ax_a.set_ylabel("pseudo-spectral acceleration PSa [g]")
    for ax, what in ((ax_d, "displacement"), (ax_a, "pseudo-acceleration")):
        ax.set_xlabel("period T [s]")
        ax.set_title(f"{what} spectrum, {zeta:.0%} damping")
        ax.grid(which="both", alpha=0.3)
        ax.legend(fontsize=8)
    fig.tight_layout()
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=110)
    plt.close(fig)
    return buffer.getvalue()


def write_spectrum(spectra: Sequence[ResponseSpectrum], folder: str | Path, stem: str = "spectrum",
                   plot: bool = True) -> list[Path]:
    """Write ``<stem>.csv`` (and ``<stem>.png``) into ``folder``; refuses to replace a file."""
    folder = Path(folder)
    table = spectrum_table(spectra)             # everything computed before anything is written
    image = plot_spectra(spectra) if plot else None
    targets = [folder / f"{stem}.csv"] + ([folder / f"{stem}.png"] if plot else [])
    existing = [str(p) for p in targets if p.exists()]
    if existing:
        raise FileExistsError(f"{existing[0]} exists: spectra are never written over a file")
    written = []
    try:
        with targets[0].open("x", encoding="utf-8", newline="") as fh:
            written.append(targets[0])
            fh.write(table)
        if plot:
            with targets[1].open("xb") as fh:
                written.append(targets[1])
                fh.write(image)
    except BaseException:
        for path in written:                    # only what this call created
            path.unlink(missing_ok=True)
        raise
    return targets
