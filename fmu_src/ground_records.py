"""Recorded ground accelerations: parsing, units, scaling and exact piecewise-linear calculus.

A :class:`Record` holds equally spaced samples ``a_i`` (m/s^2) at ``t_i = start_time + i dt``.
Between samples the signal is linear; before the first and after the last sample it is zero
(the jumps at the ends are real: records are not padded).  On that signal everything is
exact: :meth:`Record.mean_over` (what a zero-order-hold building needs so that its velocity
increments are exact), :meth:`Record.velocity` (piecewise quadratic) and
:meth:`Record.displacement` (piecewise cubic).  Uncorrected records drift in displacement;
that is a property of the data, not of the integration.

:func:`load_record` reads

* a bundled record by name (``BUNDLED``: the four "Set A" records of SLAMMER / PEER NGA-West1,
  single column in g, see ``records/CREDITS.md``),
* a PEER NGA ``.AT2`` file (4 header lines, NPTS/DT line, 5 values per line, Fortran E format),
* a single-column file (one value per line; ``dt`` must be given),
* a two-column ``time, acceleration`` CSV (header optional; the time step must be uniform),

converts units at this edge (``g`` = 9.80665 m/s^2, ``m/s2``, ``cm/s2``) and raises
:class:`RecordError` naming the file and the line for every problem.
"""
from __future__ import annotations

import csv
import math
import re
from dataclasses import dataclass, replace
from pathlib import Path
from types import MappingProxyType

import numpy as np

G = 9.80665  # standard gravity (m/s^2), the "g" of strong-motion records
UNITS = MappingProxyType({"g": G, "m/s2": 1.0, "cm/s2": 0.01})
_UNIT_ALIASES = MappingProxyType({
    "g": "g", "m/s2": "m/s2", "m/s^2": "m/s2", "m/s/s": "m/s2", "cm/s2": "cm/s2",
    "cm/s^2": "cm/s2", "cm/s/s": "cm/s2", "gal": "cm/s2", "cm/sec/sec": "cm/s2", "cm/sec2": "cm/s2",
})
FORMATS = ("auto", "at2", "column", "csv")
RECORDS_DIR = Path(__file__).resolve().parent / "records"

# A Fortran real without the leading zero, e.g. "-.8338791E-03"; used to split glued fields.
_NUMBER = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[EeDd][+-]?\d+)?")
_NPTS_DT = re.compile(r"NPTS\s*=\s*(\d+)\s*,?\s*DT\s*=\s*([0-9.EeDd+-]+)", re.IGNORECASE)


class RecordError(ValueError):
    """A record that cannot be read or used; ``path`` and ``line`` (1-based or None) locate it."""

    def __init__(self, path, line: int | None, message: str):
        self.path = str(path)
        self.line = line
        where = self.path if line is None else f"{self.path}, line {line}"
        super().__init__(f"{where}: {message}")


@dataclass(frozen=True, eq=False)
class Record:
    """An equally sampled ground acceleration (see module docstring).

    Attributes
    ----------
    name : str
    dt : float
        Sampling interval (s).
    acceleration : ndarray
        Samples (m/s^2), read-only; sample ``i`` is at ``start_time + i dt``.
    source : str
        File the samples were read from.
    credit : str
        Who recorded and processed it (to be shown with results).
    start_time : float
        Time of the first sample (s); ``load_record(time_shift=...)`` sets it.
    """

    name: str
    dt: float
    acceleration: np.ndarray
    source: str = ""
    credit: str = ""
    start_time: float = 0.0

    def __post_init__(self):
        a = np.array(self.acceleration, dtype=float).reshape(-1)
        if not (math.isfinite(self.dt) and self.dt > 0.0):
            raise ValueError(f"record {self.name!r}: dt = {self.dt!r} s must be finite and > 0")
        if a.size < 2:
            raise ValueError(f"record {self.name!r}: {a.size} sample(s); at least 2 are needed")
        if not np.all(np.isfinite(a)):
            raise ValueError(f"record {self.name!r}: sample {int(np.flatnonzero(~np.isfinite(a))[0])} is not finite")
        if not math.isfinite(self.start_time):
            raise ValueError(f"record {self.name!r}: start_time = {self.start_time!r} s is not finite")
        a.setflags(write=False)
        object.__setattr__(self, "acceleration", a)
        object.__setattr__(self, "dt", float(self.dt))
        object.__setattr__(self, "start_time", float(self.start_time))
        # Integrals at the samples: V_i = int a, D_i = int V (exact for piecewise-linear a).
        dt = self.dt
        v = np.concatenate(([0.0], np.cumsum(0.5 * dt * (a[:-1] + a[1:]))))
        d = np.concatenate(([0.0], np.cumsum(dt * v[:-1] + dt * dt * (2.0 * a[:-1] + a[1:]) / 6.0)))
        for arr in (v, d):
            arr.setflags(write=False)
        object.__setattr__(self, "_v", v)
        object.__setattr__(self, "_d", d)

    # -- summary ---------------------------------------------------------------------------------
    @property
    def npts(self) -> int:
        return int(self.acceleration.size)

    @property
    def duration(self) -> float:
        """Record length ``(npts - 1) dt`` (s)."""
        return (self.npts - 1) * self.dt

    @property
    def end_time(self) -> float:
        """Time of the last sample (s); the motion is zero afterwards."""
        return self.start_time + self.duration

    @property
    def pga(self) -> float:
        """Peak ground acceleration ``max |a|`` (m/s^2)."""
        return float(np.max(np.abs(self.acceleration)))

    @property
    def pga_g(self) -> float:
        return self.pga / G

    @property
    def times(self) -> np.ndarray:
        return self.start_time + self.dt * np.arange(self.npts)

    def scaled(self, factor: float) -> "Record":
        """The same record with every sample multiplied by ``factor``."""
        if not math.isfinite(factor):
            raise ValueError(f"scale factor {factor!r} is not finite")
        return replace(self, acceleration=self.acceleration * float(factor))

    def shifted(self, time_shift: float) -> "Record":
        """The same record starting ``time_shift`` (s) later (earlier if negative)."""
        return replace(self, start_time=self.start_time + float(time_shift))

    # -- piecewise-linear calculus ---------------------------------------------------------------
    def _locate(self, t):
        """Sample index ``k`` (clipped to the last interval) and local time ``s`` in it."""
        x = (np.asarray(t, dtype=float) - self.start_time) / self.dt
        k = np.clip(np.floor(x), 0, self.npts - 2).astype(np.intp)
        return x, k, (x - k) * self.dt

    def _scalar(self, t: float, order: int) -> float:
        """Fast path of at/velocity/displacement for one time (the FMU calls these per step)."""
        x = (t - self.start_time) / self.dt
        last = self.npts - 1
        if x < 0.0 or (order == 0 and x > last):
            return 0.0
        if x >= last and order > 0:
            return float(self._v[-1]) if order == 1 else float(self._d[-1] + self._v[-1] * (t - self.end_time))
        k = min(int(x), last - 1)
        s = (x - k) * self.dt
        a0 = float(self.acceleration[k])
        slope = (float(self.acceleration[k + 1]) - a0) / self.dt
        if order == 0:
            return a0 + slope * s
        if order == 1:
            return float(self._v[k]) + s * (a0 + slope * s / 2.0)
        return float(self._d[k]) + s * (float(self._v[k]) + s * (a0 / 2.0 + slope * s / 6.0))

    def at(self, t):
        """Acceleration (m/s^2) at time(s) ``t`` (s): linear between samples, 0 outside."""
        if isinstance(t, (float, int)):
            return self._scalar(float(t), 0)
        x, k, s = self._locate(t)
        a = self.acceleration
        val = a[k] + (a[k + 1] - a[k]) * (s / self.dt)
        out = np.where((x >= 0.0) & (x <= self.npts - 1), val, 0.0)
        return float(out) if out.ndim == 0 else out

    def velocity(self, t):
        """Ground velocity ``int_{-inf}^t a`` (m/s), exact for the piecewise-linear signal."""
        if isinstance(t, (float, int)):
            return self._scalar(float(t), 1)
        x, k, s = self._locate(t)
        a, dt = self.acceleration, self.dt
        inside = self._v[k] + a[k] * s + (a[k + 1] - a[k]) * s * s / (2.0 * dt)
        out = np.where(x <= 0.0, 0.0, np.where(x >= self.npts - 1, self._v[-1], inside))
        return float(out) if out.ndim == 0 else out

    def displacement(self, t):
        """Ground displacement ``int_{-inf}^t velocity`` (m), exact for the piecewise-linear signal."""
        if isinstance(t, (float, int)):
            return self._scalar(float(t), 2)
        x, k, s = self._locate(t)
        a, dt = self.acceleration, self.dt
        inside = (self._d[k] + self._v[k] * s + a[k] * s * s / 2.0
                  + (a[k + 1] - a[k]) * s ** 3 / (6.0 * dt))
        after = self._d[-1] + self._v[-1] * (np.asarray(t, dtype=float) - self.end_time)
        out = np.where(x <= 0.0, 0.0, np.where(x >= self.npts - 1, after, inside))
        return float(out) if out.ndim == 0 else out

    def mean_over(self, t0, t1):
        """Exact mean acceleration (m/s^2) over ``[t0, t1]`` (s); ``at(t0)`` if ``t1 == t0``."""
        if isinstance(t0, (float, int)) and isinstance(t1, (float, int)):
            if t1 < t0:
                raise ValueError(f"mean_over(t0, t1) needs t1 >= t0; got t0 = {t0!r}, t1 = {t1!r}")
            if t1 == t0:
                return self._scalar(float(t0), 0)
            return (self._scalar(float(t1), 1) - self._scalar(float(t0), 1)) / (t1 - t0)
        t0 = np.asarray(t0, dtype=float)
        t1 = np.asarray(t1, dtype=float)
        if np.any(t1 < t0):
            raise ValueError("mean_over(t0, t1) needs t1 >= t0")
        span = t1 - t0
        with np.errstate(divide="ignore", invalid="ignore"):
            out = np.where(span > 0.0, (self.velocity(t1) - self.velocity(t0)) / np.where(span > 0, span, 1.0),
                           self.at(t0))
        return float(out) if out.ndim == 0 else out


# -- bundled records ------------------------------------------------------------------------------
@dataclass(frozen=True)
class BundledRecord:
    """Metadata of a record shipped in ``fmu_src/records`` (from its ``records_manifest.csv``)."""

    name: str
    file: str
    event: str
    station: str
    component: str
    dt: float          # s
    npts: int
    pga_g: float       # documented PGA (g)
    duration: float    # documented record length (s)
    units: str
    credit: str

    @property
    def path(self) -> Path:
        return RECORDS_DIR / self.file


def _bundled_name(file: str) -> str:
    # "elcentro_1940_NS_slammer_ELC-180.txt" -> "elcentro1940"
    word, year = file.split("_")[:2]
    return f"{word}{year}"


def _read_manifest() -> MappingProxyType:
    manifest = RECORDS_DIR / "records_manifest.csv"
    if not manifest.exists():  # a stripped install: no bundled records, files still load
        return MappingProxyType({})
    entries = {}
    with manifest.open(newline="", encoding="utf-8") as fh:
        for row in csv.DictReader(fh):
            credit = (f"{row['event']}, {row['station']}, component {row['component']}; "
                      f"recorded by {row['recorded_by']}; processing: {row['processing']} "
                      f"(Jibson et al. 2013, USGS TM 12-B1; Chiou et al. 2008)")
            name = _bundled_name(row["file"])
            entries[name] = BundledRecord(
                name=name, file=row["file"], event=row["event"], station=row["station"],
                component=row["component"], dt=float(row["dt_s"]), npts=int(row["npts"]),
                pga_g=float(row["pga_g"]), duration=float(row["record_length_s"]),
                units=row["units"], credit=credit)
    return MappingProxyType(entries)


BUNDLED = _read_manifest()


# -- parsers --------------------------------------------------------------------------------------
def _lines(path: Path) -> list[str]:
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        raise RecordError(path, None, "file not found") from None
    except IsADirectoryError:
        raise RecordError(path, None, "is a directory, not a record file") from None
    except OSError as exc:
        raise RecordError(path, None, f"cannot be read: {exc.strerror}") from None
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError:
        text = raw.decode("latin-1")
    return text.splitlines()  # handles LF, CRLF and CR


def _number(path: Path, lineno: int, token: str) -> float:
    try:
        value = float(token.replace("D", "E").replace("d", "e"))
    except ValueError:
        raise RecordError(path, lineno, f"{token!r} is not a number") from None
    if not math.isfinite(value):
        raise RecordError(path, lineno, f"{token!r} is not a finite number")
    return value


def _numbers(path: Path, lineno: int, line: str) -> list[float]:
    values = []
    for token in line.replace(",", " ").split():
        pieces = _NUMBER.findall(token)
        if len(pieces) > 1 and "".join(pieces) == token:  # full-width Fortran fields glued together
            values.extend(_number(path, lineno, p) for p in pieces)
        else:
            values.append(_number(path, lineno, token))
    return values


def _parse_at2(path: Path, lines: list[str]):
    """PEER NGA .AT2 -> (samples, dt, units or None)."""
    if len(lines) < 5:
        raise RecordError(path, len(lines) or None,
                          f"an AT2 file has 4 header lines and data; this one has {len(lines)} line(s)")
    units = None
    header = lines[2].strip()
    m = re.search(r"UNITS\s+OF\s+(\S+)", header, re.IGNORECASE)
    if "ACCELERATION" not in header.upper() or m is None:
        raise RecordError(path, 3, f"expected 'ACCELERATION TIME SERIES IN UNITS OF <unit>', found {header!r}")
    unit_word = m.group(1).lower()
    units = _UNIT_ALIASES.get(unit_word)
    if units is None:
        raise RecordError(path, 3, f"unknown unit {m.group(1)!r} (known: G, M/S/S, CM/S/S, GAL)")
    line4 = lines[3]
    m = _NPTS_DT.search(line4)
    if m:
        npts, dt = int(m.group(1)), _number(path, 4, m.group(2))
    else:  # NGA-West1 style: "4164    0.0100    NPTS, DT" -> first integer, next float
        tokens = _NUMBER.findall(line4)
        ints = [i for i, tok in enumerate(tokens) if re.fullmatch(r"\d+", tok)]
        if not ints or ints[0] + 1 >= len(tokens):
            raise RecordError(path, 4, f"expected 'NPTS= <n>, DT= <s> SEC' or '<n> <dt> NPTS, DT', found {line4.strip()!r}")
        npts, dt = int(tokens[ints[0]]), _number(path, 4, tokens[ints[0] + 1])
    if not dt > 0.0:
        raise RecordError(path, 4, f"DT = {dt!r} s must be > 0")
    values: list[float] = []
    last = 4
    for lineno, line in enumerate(lines[4:], start=5):
        if line.strip():
            values.extend(_numbers(path, lineno, line))
            last = lineno
            if len(values) > npts:
                raise RecordError(path, lineno, f"more values than NPTS = {npts} (header line 4)")
    if len(values) != npts:
        raise RecordError(path, last, f"{len(values)} values, but NPTS = {npts} (header line 4)")
    return np.array(values), dt, units


def _parse_column(path: Path, lines: list[str]):
    values = []
    for lineno, line in enumerate(lines, start=1):
        text = line.split("#", 1)[0].strip()
        if not text:
            continue
        tokens = text.replace(",", " ").split()
        if len(tokens) != 1:
            raise RecordError(path, lineno, f"a single-column file has one value per line; found {len(tokens)} "
                                            f"({text!r}); use format='csv' for time,acceleration columns")
        values.append(_number(path, lineno, tokens[0]))
    return np.array(values)


def _parse_csv(path: Path, lines: list[str]):
    """Two columns ``t, a`` -> (samples, dt, first time)."""
    times, values, linenos = [], [], []
    for lineno, line in enumerate(lines, start=1):
        text = line.strip()
        if not text or text.startswith("#"):
            continue
        cells = [c.strip() for c in re.split(r"[,;\t]|\s+", text) if c.strip()]
        if not times and not values:
            try:
                float(cells[0])
            except ValueError:
                continue  # header line
        if len(cells) != 2:
            raise RecordError(path, lineno, f"expected 2 columns (time, acceleration), found {len(cells)}: {text!r}")
        times.append(_number(path, lineno, cells[0]))
        values.append(_number(path, lineno, cells[1]))
        linenos.append(lineno)
    if len(times) < 2:
        raise RecordError(path, linenos[-1] if linenos else None, f"{len(times)} data row(s); at least 2 are needed")
    t = np.array(times)
    dt = float(t[-1] - t[0]) / (len(t) - 1)
    if not dt > 0.0:
        raise RecordError(path, linenos[-1], "time does not increase")
    # Times written with a few decimals deviate from the grid by round-off only; 0.1 % of dt
    # accepts that and rejects any real gap or repeated sample.
    off = np.abs(t - (t[0] + dt * np.arange(len(t))))
    bad = np.flatnonzero(off > 1e-3 * dt)
    if bad.size:
        i = int(bad[0])
        raise RecordError(path, linenos[i], f"non-uniform time step: t = {t[i]!r} s, expected {t[0] + i * dt:.9g} s "
                                            f"on the uniform grid dt = {dt:.9g} s")
    return np.array(values), dt, float(t[0])


def _sniff(path: Path, lines: list[str]) -> str:
    suffix = path.suffix.lower()
    if suffix == ".at2":
        return "at2"
    if suffix == ".csv":
        return "csv"
    head = "\n".join(lines[:5]).upper()
    if "NPTS" in head or "PEER" in head:
        return "at2"
    for line in lines[:20]:
        text = line.split("#", 1)[0].strip()
        if text:
            return "csv" if len(re.split(r"[,;\t]|\s+", text)) == 2 else "column"
    return "column"


def _unit_name(units: str) -> str:
    key = _UNIT_ALIASES.get(str(units).strip().lower())
    if key is None:
        raise ValueError(f"units = {units!r} is not allowed: one of {', '.join(UNITS)}")
    return key


def load_record(spec, fmt: str = "auto", dt: float | None = None, units: str = "g", scale: float = 1.0,
                target_pga: float | None = None, time_shift: float = 0.0,
                records_dir: str | Path | None = None) -> Record:
    """Load a ground acceleration record in SI units.

    Parameters
    ----------
    spec : str or path
        A bundled name (``BUNDLED``: ``elcentro1940 kobe1995 sanfernando1971 parkfield1966``) or a file.
    fmt : {"auto", "at2", "column", "csv"}
        File format; ``auto`` uses the suffix (``.AT2``, ``.csv``) and then the content.
    dt : float, optional
        Sampling interval (s); required for single-column files, checked against AT2/CSV files
        and bundled records when given.  ``None`` or ``<= 0`` means not given.
    units : {"g", "m/s2", "cm/s2"}
        Units of the values in the file (an AT2 header states its own; they must agree).
    scale : float
        Factor applied to the samples (ignored when ``target_pga`` is given).
    target_pga : float, optional
        Scale the record so that its PGA is this value (m/s^2); ``None`` or ``<= 0``: no target.
    time_shift : float
        The first sample is at ``t = time_shift`` (s); negative values skip the beginning.
    records_dir : path, optional
        Folder of the bundled records; default: ``records/`` beside this module.  An FMU passes
        its own ``resources/fmu_src/records``: every FMU of a process shares one imported
        ``fmu_src``, whose folder may belong to another, already unloaded FMU.
    """
    if fmt not in FORMATS:
        raise ValueError(f"format = {fmt!r} is not allowed: one of {', '.join(FORMATS)}")
    unit = _unit_name(units)
    if dt is not None and not (math.isfinite(dt)):
        raise ValueError(f"dt = {dt!r} s is not finite")
    given_dt = dt if dt is not None and dt > 0.0 else None
    credit = ""
    key = str(spec)
    start = 0.0
    if key in BUNDLED:
        meta = BUNDLED[key]
        path = Path(records_dir) / meta.file if records_dir is not None else meta.path
        if unit != meta.units:
            raise RecordError(path, None, f"bundled record {key!r} is in {meta.units}; units = {units!r} contradicts it")
        samples = _parse_column(path, _lines(path))
        if samples.size != meta.npts:
            raise RecordError(path, None, f"{samples.size} samples, the manifest says {meta.npts}")
        file_dt, name, credit = meta.dt, key, meta.credit
    else:
        path = Path(spec)
        lines = _lines(path)
        kind = _sniff(path, lines) if fmt == "auto" else fmt
        name = path.stem
        file_dt = None
        if kind == "at2":
            samples, file_dt, file_units = _parse_at2(path, lines)
            if file_units != unit:
                raise RecordError(path, 3, f"the header states units of {file_units}, but units = {units!r} was given")
        elif kind == "csv":
            samples, file_dt, start = _parse_csv(path, lines)
        else:
            samples = _parse_column(path, lines)
            if given_dt is None:
                raise RecordError(path, None, "a single-column file has no time step: give dt (s)")
        if samples.size < 2:
            raise RecordError(path, None, f"{samples.size} sample(s); a record needs at least 2")
    if file_dt is not None and given_dt is not None and not math.isclose(given_dt, file_dt, rel_tol=1e-6):
        raise RecordError(path, None, f"dt = {given_dt!r} s was given but the record's time step is {file_dt:.9g} s")
    record = Record(name=name, dt=file_dt if file_dt is not None else given_dt,
                    acceleration=samples * UNITS[unit], source=str(path), credit=credit,
                    start_time=start + float(time_shift))
    if target_pga is not None and target_pga > 0.0:
        if not math.isfinite(target_pga):
            raise ValueError(f"target_pga = {target_pga!r} m/s^2 is not finite")
        if record.pga == 0.0:
            raise RecordError(path, None, "all samples are zero: cannot scale to a target PGA")
        return record.scaled(target_pga / record.pga)
    if scale != 1.0:
        return record.scaled(scale)
    return record
