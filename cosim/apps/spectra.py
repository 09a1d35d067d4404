"""Response spectra of records: computed for named records or files, written as a CSV table and a
log-log plot, both with units (``pounding-cosim spectrum RECORD ...``).

The numbers come from :func:`fmu_src.response_spectrum.response_spectrum` (exact for the
piecewise-linear record, peaks between samples included); :func:`record_spectra` loads the
records as ``ground_motion.fmu`` plays them (:func:`fmu_src.ground_records.load_record`) and
bounds the work before any is done.  Files are created exclusively: an existing file is never
replaced.
"""
from __future__ import annotations

import csv
import io
from pathlib import Path
from typing import Sequence

import numpy as np

from fmu_src.ground_records import G, load_record
from fmu_src.response_spectrum import (DEFAULT_DAMPING, DEFAULT_PERIOD_COUNT, DEFAULT_PERIOD_RANGE, PERIOD_LIMITS,
                                       ResponseSpectrum, default_periods, response_spectrum)

#: Most samples x periods one command computes.  The exact spectrum costs about 20 us per
#: sample and period on one core of the reference machine (Kobe, 2237 samples x 100 periods:
#: 5 s), so the limit, 5e6, is about 2 minutes: a request beyond it is refused at once.
MAX_SAMPLE_PERIODS = 5_000_000
#: Most periods in one table (a log grid of 1000 points per 3.7 decades is finer than any plot)
MAX_PERIODS = 1000

#: Columns written per record, after ``period_s``: (suffix, unit label, value of a spectrum).
COLUMNS = (
    ("Sd_m", "m", lambda s: s.displacement),
    ("PSv_m_s", "m/s", lambda s: s.pseudo_velocity),
    ("PSa_m_s2", "m/s^2", lambda s: s.pseudo_acceleration),
    ("PSa_g", "g", lambda s: s.pseudo_acceleration / G),
    ("t_peak_s", "s", lambda s: s.peak_time),
)


def period_grid(text: Sequence[str] | None) -> np.ndarray:
    """Periods (s) from the command line: ``None`` (the default grid, DEFAULT_PERIOD_COUNT periods
    log-spaced over DEFAULT_PERIOD_RANGE), explicit values ``["0.1", "0.5", "1"]``, or one
    ``"START:STOP:NUM"`` for NUM periods log-spaced from START to STOP."""
    if not text:
        return default_periods(DEFAULT_PERIOD_COUNT, *DEFAULT_PERIOD_RANGE)
    lo, hi = PERIOD_LIMITS
    if len(text) == 1 and ":" in text[0]:
        parts = text[0].split(":")
        try:
            start, stop, num = float(parts[0]), float(parts[1]), int(parts[2])
            if len(parts) != 3:
                raise ValueError
        except (ValueError, IndexError):
            raise ValueError(f"--periods {text[0]!r}: write START:STOP:NUM, e.g. 0.02:10:100 "
                             f"(NUM periods log-spaced from START to STOP, in s)") from None
        if not (lo <= start < stop <= hi) or not 2 <= num <= MAX_PERIODS:
            raise ValueError(f"--periods {text[0]!r}: needs {lo:g} <= START < STOP <= {hi:g} s and "
                             f"2 <= NUM <= {MAX_PERIODS}")
        return default_periods(num, start, stop)
    try:
        periods = np.array([float(t) for t in text])
    except ValueError:
        raise ValueError(f"--periods {' '.join(text)}: periods must be numbers in s (or one START:STOP:NUM)") from None
    bad = [t for t, p in zip(text, periods) if not lo <= p <= hi]
    if bad:
        raise ValueError(f"--periods: period {bad[0]} s is outside the allowed range {lo:g} <= T <= {hi:g} s")
    if periods.size > MAX_PERIODS:
        raise ValueError(f"--periods: {periods.size} periods; at most {MAX_PERIODS}")
    return np.unique(periods)


def record_spectra(records: Sequence[str], periods=None, damping: float = DEFAULT_DAMPING, *,
                   fmt: str = "auto", dt: float | None = None, units: str = "g",
                   target_pga_g: float | None = None) -> list[ResponseSpectrum]:
    """The response spectra of ``records`` (bundled names or files, read as ``ground_motion.fmu``
    reads them: ``fmt``, ``dt`` (s), ``units``), optionally scaled to a PGA of ``target_pga_g``
    (g), at ``periods`` (s; default grid) and ``damping`` (-).  Every record is read and the
    work bounded (MAX_SAMPLE_PERIODS) before any spectrum is computed."""
    periods = default_periods() if periods is None else np.asarray(periods, dtype=float)
    loaded = [load_record(spec, fmt=fmt, dt=dt, units=units, target_pga_g=target_pga_g or None)
              for spec in records]
    work = sum(r.npts for r in loaded) * periods.size
    if work > MAX_SAMPLE_PERIODS:
        raise ValueError(f"{sum(r.npts for r in loaded)} samples x {periods.size} periods = {work:.3g} "
                         f"oscillator-samples; the limit is {MAX_SAMPLE_PERIODS:.0e} (about 2 minutes): "
                         f"give fewer periods (--periods) or fewer records")
    names = _unique_names([r.name for r in loaded])
    return [response_spectrum(r.acceleration, r.dt, periods, damping, name) for r, name in zip(loaded, names)]


def _unique_names(names: Sequence[str]) -> list[str]:
    """Record names, numbered where two files share a name."""
    out = []
    for name in names:
        label, k = name, 2
        while label in out:
            label, k = f"{name}_{k}", k + 1
        out.append(label)
    return out


def summary_lines(spectra: Sequence[ResponseSpectrum]) -> list[str]:
    """One line per spectrum for the terminal: PGA, the largest PSa and Sd and their periods."""
    lines = []
    for s in spectra:
        psa = s.pseudo_acceleration
        i, j = int(np.argmax(psa)), int(np.argmax(s.displacement))
        lines.append(f"{s.name}: PGA {s.pga / G:.3g} g; {s.damping:.0%} damping: largest PSa {psa[i] / G:.3g} g "
                     f"at T = {s.periods[i]:.3g} s, largest Sd {s.displacement[j]:.4g} m at T = {s.periods[j]:.3g} s "
                     f"({s.periods.size} periods {s.periods[0]:.3g}-{s.periods[-1]:.3g} s)")
    return lines


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
