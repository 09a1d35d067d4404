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
:class:`RecordError` naming the file, the line and the value as written for every problem.

Files are text in UTF-8 (with or without a byte-order mark), UTF-16 (with a byte-order mark,
or ASCII text with every other byte zero) or Latin-1.  Before anything is read a file must be a
regular file of at most ``MAX_RECORD_BYTES``, and a record holds at most ``MAX_RECORD_SAMPLES``
samples: a device such as ``/dev/zero`` or a huge file is refused at once, never read into memory.
A record whose PGA in its stated unit is outside ``PLAUSIBLE_PGA_G`` carries a warning in
:attr:`Record.warnings` (e.g. a record in cm/s^2 read as g).

Scaling (:func:`scale_factor`): ``scale``, or exactly one target, ``target_pga`` (m/s^2),
``target_pga_g`` (g) or ``target_sa`` (m/s^2, the pseudo-spectral acceleration at ``sa_period``
with damping ``sa_damping``, :mod:`fmu_src.response_spectrum`).  A scaled PGA above
``MAX_PGA_G`` is refused.
"""
from __future__ import annotations

import codecs
import csv
import io
import math
import re
import stat
from dataclasses import dataclass, replace
from pathlib import Path
from types import MappingProxyType
from typing import Iterator, Mapping

import numpy as np

G = 9.80665  # standard gravity (m/s^2), the "g" of strong-motion records
#: Largest record file read (bytes).  A million samples written as AT2 (about 15 characters
#: each) or as a "time, acceleration" CSV (about 25) fit; anything larger is not a record.
MAX_RECORD_BYTES = 32 * 2 ** 20
#: Most samples in one record: 200 samples/s for 5000 s (a long-period record is ~60,000).
MAX_RECORD_SAMPLES = 1_000_000
#: PGA range (g) of real strong-motion records in their stated unit; outside it a record is
#: most likely read in the wrong unit (cm/s^2 read as g is 981 times too strong).
PLAUSIBLE_PGA_G = (0.001, 5.0)
#: Largest PGA (g) a scaled record may have: far beyond any recorded motion (the seed paper's
#: Fig 8b goes to 15 g), small enough that every integral of the record stays finite.
MAX_PGA_G = 100.0
#: The scaling targets: at most one may be set (> 0) at a time; 0 or None means not set.
SCALING_TARGETS = ("target_pga", "target_pga_g", "target_sa")
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
    scale_factor : float
        Factor applied to the values of the file after the unit conversion (1 if unscaled).
    warnings : tuple of str
        Doubts about the data that do not stop a run (an implausible PGA for the stated unit).
    """

    name: str
    dt: float
    acceleration: np.ndarray
    source: str = ""
    credit: str = ""
    start_time: float = 0.0
    scale_factor: float = 1.0
    warnings: tuple[str, ...] = ()

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
        return replace(self, acceleration=self.acceleration * float(factor),
                       scale_factor=self.scale_factor * float(factor))

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

    def over_step(self, t0: float, t1: float) -> tuple[float, float, float, float]:
        """``(at(t1), mean_over(t0, t1), velocity(t1), displacement(t1))`` for one step ``t1 > t0``
        (s), each in the arithmetic of its own method (the same doubles), the velocity at ``t1``
        computed once for the mean and the velocity (ground_motion.fmu's doStep)."""
        if not t1 > t0:
            raise ValueError(f"over_step(t0, t1) needs t1 > t0; got t0 = {t0!r}, t1 = {t1!r}")
        v1 = self._scalar(t1, 1)
        mean = (v1 - self._scalar(t0, 1)) / (t1 - t0)
        return self._scalar(t1, 0), mean, v1, self._scalar(t1, 2)

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


# -- reading files --------------------------------------------------------------------------------
_UTF16_BOMS = (codecs.BOM_UTF16_LE, codecs.BOM_UTF16_BE)


def _decode(path: Path, raw: bytes) -> str:
    """Text of a record file: UTF-8 (BOM optional), UTF-16 (BOM, or ASCII with zero bytes), Latin-1."""
    if raw.startswith(codecs.BOM_UTF8):
        encoding, body = "utf-8", raw[len(codecs.BOM_UTF8):]
    elif raw.startswith(_UTF16_BOMS):
        encoding, body = "utf-16", raw               # the codec reads the BOM for the byte order
    elif b"\x00" in raw[:4096]:
        # UTF-16 without a BOM: ASCII digits leave every other byte zero
        head = raw[:4096]
        if head[1::2].count(0) > 0.9 * len(head[1::2]):
            encoding, body = "utf-16-le", raw
        elif head[0::2].count(0) > 0.9 * len(head[0::2]):
            encoding, body = "utf-16-be", raw
        else:
            raise RecordError(path, None, "holds zero bytes but is not UTF-16 text: not a record file")
    else:
        try:
            return raw.decode("utf-8")
        except UnicodeDecodeError:
            return raw.decode("latin-1")             # old files with a degree sign in a header
    try:
        text = body.decode(encoding)
    except UnicodeDecodeError as exc:
        raise RecordError(path, None, f"is not valid {encoding.upper()} text (byte {exc.start}: "
                                      f"{exc.reason})") from None
    return text.lstrip("\ufeff")


class _Text:
    """The decoded text of a record file; its lines are produced lazily, numbered from 1."""

    def __init__(self, path: Path, text: str):
        self.path = path
        self.text = text

    def lines(self) -> Iterator[tuple[int, str]]:
        for number, line in enumerate(io.StringIO(self.text, newline=None), start=1):
            yield number, line.rstrip("\n")

    def head(self, count: int) -> list[str]:
        out = []
        for _, line in self.lines():
            if len(out) == count:
                break
            out.append(line)
        return out


def _read(path: Path, max_bytes: int = MAX_RECORD_BYTES) -> _Text:
    """Check that ``path`` is a regular file within the size limit, then read and decode it."""
    try:
        info = path.stat()
    except FileNotFoundError:
        raise RecordError(path, None, "file not found") from None
    except OSError as exc:
        raise RecordError(path, None, f"cannot be read: {exc.strerror}") from None
    if stat.S_ISDIR(info.st_mode):
        raise RecordError(path, None, "is a directory, not a record file")
    if not stat.S_ISREG(info.st_mode):
        raise RecordError(path, None, "is not a regular file (a device, pipe or socket): "
                                      "a record must be a text file")
    limit = f"the limit of a record file is {max_bytes / 2 ** 20:g} MiB ({MAX_RECORD_SAMPLES:,} samples)"
    if info.st_size > max_bytes:
        raise RecordError(path, None, f"is {info.st_size / 2 ** 20:.1f} MiB; {limit}")
    try:
        with path.open("rb") as fh:
            raw = fh.read(max_bytes + 1)            # a file growing while read is still bounded
    except OSError as exc:
        raise RecordError(path, None, f"cannot be read: {exc.strerror}") from None
    if len(raw) > max_bytes:
        raise RecordError(path, None, f"is larger than {max_bytes / 2 ** 20:g} MiB; {limit}")
    return _Text(path, _decode(path, raw))


# -- parsers --------------------------------------------------------------------------------------
def _number(path: Path, lineno: int, token: str) -> float:
    try:
        value = float(token.replace("D", "E").replace("d", "e"))
    except ValueError:
        raise RecordError(path, lineno, f"{token!r} is not a number") from None
    if not math.isfinite(value):
        raise RecordError(path, lineno, f"{token!r} is not a finite number")
    return value


def _is_number(token: str) -> bool:
    try:
        float(token.replace("D", "E").replace("d", "e"))
    except ValueError:
        return False
    return True


def _numbers(path: Path, lineno: int, line: str) -> list[float]:
    values = []
    for token in line.replace(",", " ").split():
        pieces = _NUMBER.findall(token)
        if len(pieces) > 1 and "".join(pieces) == token:  # full-width Fortran fields glued together
            values.extend(_number(path, lineno, p) for p in pieces)
        else:
            values.append(_number(path, lineno, token))
    return values


def _too_many(path: Path, lineno: int) -> RecordError:
    return RecordError(path, lineno, f"more than {MAX_RECORD_SAMPLES:,} samples, the limit of a record")


def _parse_at2(path: Path, text: _Text):
    """PEER NGA .AT2 -> (samples, dt, units or None)."""
    lines = text.head(5)
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
        npts_text, dt_text = m.group(1), m.group(2)
    else:  # NGA-West1 style: "4164    0.0100    NPTS, DT" -> first integer, next float
        tokens = _NUMBER.findall(line4)
        ints = [i for i, tok in enumerate(tokens) if re.fullmatch(r"\d+", tok)]
        if not ints or ints[0] + 1 >= len(tokens):
            raise RecordError(path, 4, f"expected 'NPTS= <n>, DT= <s> SEC' or '<n> <dt> NPTS, DT', found {line4.strip()!r}")
        npts_text, dt_text = tokens[ints[0]], tokens[ints[0] + 1]
    dt = _number(path, 4, dt_text)
    npts = int(npts_text)
    if npts > MAX_RECORD_SAMPLES:
        raise RecordError(path, 4, f"NPTS = {npts_text} is more than {MAX_RECORD_SAMPLES:,} samples, "
                                   f"the limit of a record")
    if not dt > 0.0:
        raise RecordError(path, 4, f"DT = {dt_text} s must be > 0")
    values: list[float] = []
    last = 4
    for lineno, line in text.lines():
        if lineno <= 4 or not line.strip():
            continue
        values.extend(_numbers(path, lineno, line))
        last = lineno
        if len(values) > npts:
            raise RecordError(path, lineno, f"more values than NPTS = {npts} (header line 4)")
    if len(values) != npts:
        raise RecordError(path, last, f"{len(values)} values, but NPTS = {npts} (header line 4)")
    return np.array(values), dt, units


def _plain_column(text: str) -> np.ndarray | None:
    """The samples of a single-column text with one plain number on every line (no comment,
    comma, Fortran exponent ``D``, blank line, or anything else), parsed by ``float`` line by line
    as :func:`_parse_column` parses them; None for any other text, which :func:`_parse_column`
    then reads (and explains) line by line.  A bundled record took 2 ms to read the careful way,
    inside a run's measured time (ground_motion.fmu reads its record at initialisation)."""
    if "#" in text or "," in text or "d" in text or "D" in text:
        return None
    lines = text.replace("\r\n", "\n").replace("\r", "\n").split("\n")   # the universal newlines of _Text
    if lines and lines[-1] == "":
        lines.pop()                        # the final newline
    if len(lines) > MAX_RECORD_SAMPLES:
        return None
    try:
        values = np.array([float(line) for line in lines])
    except ValueError:                     # a blank line, two values, a word: read it carefully
        return None
    if values.size and not np.isfinite(values).all():
        return None
    return values


def _parse_column(path: Path, text: _Text):
    plain = _plain_column(text.text)
    return plain if plain is not None else _parse_column_lines(path, text)


def _parse_column_lines(path: Path, text: _Text):
    """A single-column file line by line: comments, commas, blank lines, Fortran exponents, and
    the line of the first problem."""
    values = []
    for lineno, line in text.lines():
        data = line.split("#", 1)[0].strip()
        if not data:
            continue
        tokens = data.replace(",", " ").split()
        if len(tokens) != 1:
            raise RecordError(path, lineno, f"a single-column file has one value per line; found {len(tokens)} "
                                            f"({data!r}); use format='csv' for time,acceleration columns")
        values.append(_number(path, lineno, tokens[0]))
        if len(values) > MAX_RECORD_SAMPLES:
            raise _too_many(path, lineno)
    return np.array(values)


def _cells(text: str) -> list[str]:
    return [c.strip() for c in re.split(r"[,;\t]|\s+", text) if c.strip()]


def _parse_csv(path: Path, text: _Text):
    """Two columns ``t, a`` -> (samples, dt, first time).

    Lines above the data are a header only when none of their cells is a number (``time, acc``);
    any other line is data, so no row is ever dropped.
    """
    times, values, linenos, written = [], [], [], []
    for lineno, line in text.lines():
        data = line.strip()
        if not data or data.startswith("#"):
            continue
        cells = _cells(data)
        if not times and not any(_is_number(c) for c in cells):
            continue                                 # a header line above the data: no cell is a number
        if len(cells) != 2:
            raise RecordError(path, lineno, f"expected 2 columns (time, acceleration), found {len(cells)}: {data!r}")
        times.append(_number(path, lineno, cells[0]))
        values.append(_number(path, lineno, cells[1]))
        linenos.append(lineno)
        written.append(cells[0])
        if len(times) > MAX_RECORD_SAMPLES:
            raise _too_many(path, lineno)
    if len(times) < 2:
        raise RecordError(path, linenos[-1] if linenos else None, f"{len(times)} data row(s); at least 2 are needed")
    t = np.array(times)
    step = np.diff(t)
    back = np.flatnonzero(step <= 0.0)
    if back.size:
        i = int(back[0]) + 1
        raise RecordError(path, linenos[i], f"time {written[i]} s does not increase "
                                            f"(line {linenos[i - 1]}: {written[i - 1]} s)")
    # A missing or repeated sample is a jump at its own line: compare each step with the typical
    # one.  1 % of dt is far above the round-off of times written with a few decimals.
    typical = float(np.median(step))
    jump = np.flatnonzero(np.abs(step - typical) > 1e-2 * typical)
    if jump.size:
        i = int(jump[0]) + 1
        raise RecordError(path, linenos[i], f"time jumps from {written[i - 1]} s (line {linenos[i - 1]}) to "
                                            f"{written[i]} s, a step of {float(step[i - 1]):.6g} s; the record's "
                                            f"time step is {typical:.6g} s")
    dt = float(t[-1] - t[0]) / (len(t) - 1)
    # Times written with a few decimals deviate from the grid by round-off only; 0.1 % of dt
    # accepts that and rejects a slow drift of the time step.
    off = np.abs(t - (t[0] + dt * np.arange(len(t))))
    bad = np.flatnonzero(off > 1e-3 * dt)
    if bad.size:
        i = int(bad[0])
        raise RecordError(path, linenos[i], f"non-uniform time step: t = {written[i]} s, expected "
                                            f"{t[0] + i * dt:.9g} s on the uniform grid dt = {dt:.9g} s")
    return np.array(values), dt, float(t[0])


def _sniff(path: Path, text: _Text) -> str:
    suffix = path.suffix.lower()
    if suffix == ".at2":
        return "at2"
    if suffix == ".csv":
        return "csv"
    lines = text.head(20)
    head = "\n".join(lines[:5]).upper()
    if "NPTS" in head or "PEER" in head:
        return "at2"
    for line in lines:
        data = line.split("#", 1)[0].strip()
        if data:
            return "csv" if len(re.split(r"[,;\t]|\s+", data)) == 2 else "column"
    return "column"


def _unit_name(units: str) -> str:
    key = _UNIT_ALIASES.get(str(units).strip().lower())
    if key is None:
        raise ValueError(f"units = {units!r} is not allowed: one of {', '.join(UNITS)}")
    return key


def _plausibility(record: "Record", units: str) -> tuple[str, ...]:
    """A warning when the PGA in the stated unit is outside ``PLAUSIBLE_PGA_G``."""
    low, high = PLAUSIBLE_PGA_G
    pga_g = record.pga_g
    if low <= pga_g <= high:
        return ()
    what = "all samples are zero" if pga_g == 0.0 else f"its PGA read with units = {units!r} is {pga_g:.4g} g"
    return (f"{record.source}: {what}, outside {low:g}-{high:g} g of real strong-motion records: "
            f"check units (a record in cm/s2 read as g is {G * 100:.0f} times too strong)",)


# -- scaling ----------------------------------------------------------------------------------------
def _given(value) -> bool:
    return value is not None and value != 0.0


def scaling_conflict(target_pga=None, target_pga_g=None, target_sa=None) -> str | None:
    """Why a set of scaling targets is not allowed (more than one set, > 0), or None."""
    values = dict(target_pga=target_pga, target_pga_g=target_pga_g, target_sa=target_sa)
    chosen = [f"{k} = {v!r}" for k, v in values.items() if _given(v)]
    if len(chosen) > 1:
        return (f"at most one of {', '.join(SCALING_TARGETS)} may be set; got {' and '.join(chosen)} "
                f"(set the others to 0)")
    return None


def scale_factor(record: "Record", scale: float = 1.0, target_pga: float | None = None,
                 target_pga_g: float | None = None, target_sa: float | None = None,
                 sa_period: float | None = None, sa_damping: float | None = None) -> float:
    """The factor that scales ``record`` as asked (see module docstring).

    ``target_pga`` (m/s^2) or ``target_pga_g`` (g): PGA after scaling.  ``target_sa`` (m/s^2):
    pseudo-spectral acceleration at ``sa_period`` (s) with damping ``sa_damping`` (default 0.05)
    after scaling.  With no target, ``scale``.  A target of 0 or None is not set.
    """
    from .response_spectrum import DEFAULT_DAMPING, pseudo_acceleration

    conflict = scaling_conflict(target_pga, target_pga_g, target_sa)
    if conflict:
        raise ValueError(conflict)
    for name, value in (("target_pga", target_pga), ("target_pga_g", target_pga_g), ("target_sa", target_sa)):
        if _given(value) and not (math.isfinite(value) and value > 0.0):
            raise ValueError(f"{name} = {value!r} must be finite and > 0 (0 = not set)")
    source = record.source or record.name
    if _given(target_sa):
        if not _given(sa_period):
            raise ValueError(f"target_sa = {target_sa!r} m/s^2 needs the period sa_period (s) it applies at")
        damping = DEFAULT_DAMPING if sa_damping is None else sa_damping
        sa = pseudo_acceleration(record.acceleration, record.dt, sa_period, damping)
        if sa == 0.0:
            raise RecordError(source, None, "all samples are zero: cannot scale to a target PSa")
        factor = target_sa / sa
    elif _given(target_pga) or _given(target_pga_g):
        if record.pga == 0.0:
            raise RecordError(source, None, "all samples are zero: cannot scale to a target PGA")
        factor = (target_pga if _given(target_pga) else target_pga_g * G) / record.pga
    else:
        factor = float(scale)
        if not math.isfinite(factor):
            raise ValueError(f"scale = {scale!r} is not finite")
    pga_g = abs(factor) * record.pga_g
    if pga_g > MAX_PGA_G:
        if factor == 1.0:
            raise ValueError(f"{source}: its PGA is {pga_g:.6g} g, above the limit of {MAX_PGA_G:g} g: check "
                             f"units (a record in cm/s2 read as g is {G * 100:.0f} times too strong), or scale it")
        raise ValueError(f"{source}: scaling by {factor:.6g} gives a PGA of {pga_g:.6g} g, above the limit "
                         f"of {MAX_PGA_G:g} g")
    return factor


# -- loading ----------------------------------------------------------------------------------------
def load_record(spec, fmt: str = "auto", dt: float | None = None, units: str = "g", scale: float = 1.0,
                target_pga: float | None = None, time_shift: float = 0.0,
                records_dir: str | Path | None = None, *, target_pga_g: float | None = None,
                target_sa: float | None = None, sa_period: float | None = None,
                sa_damping: float | None = None) -> Record:
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
        Factor applied to the samples (ignored when a target is given).
    target_pga, target_pga_g, target_sa, sa_period, sa_damping : float, optional
        Scale the record to a PGA (m/s^2, or g) or to a pseudo-spectral acceleration (m/s^2) at
        ``sa_period`` (s) with damping ``sa_damping`` (-, default 0.05); at most one target;
        ``None`` or 0 means not set (:func:`scale_factor`).
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
    conflict = scaling_conflict(target_pga, target_pga_g, target_sa)
    if conflict:  # before reading anything
        raise ValueError(conflict)
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
        samples = _parse_column(path, _read(path))
        if samples.size != meta.npts:
            raise RecordError(path, None, f"{samples.size} samples, the manifest says {meta.npts}")
        file_dt, name, credit = meta.dt, key, meta.credit
    else:
        path = Path(spec)
        text = _read(path)
        kind = _sniff(path, text) if fmt == "auto" else fmt
        name = path.stem
        file_dt = None
        if kind == "at2":
            samples, file_dt, file_units = _parse_at2(path, text)
            if file_units != unit:
                raise RecordError(path, 3, f"the header states units of {file_units}, but units = {units!r} was given")
        elif kind == "csv":
            samples, file_dt, start = _parse_csv(path, text)
        else:
            samples = _parse_column(path, text)
            if given_dt is None:
                raise RecordError(path, None, "a single-column file has no time step: give dt (s)")
        if samples.size < 2:
            raise RecordError(path, None, f"{samples.size} sample(s); a record needs at least 2")
    if file_dt is not None and given_dt is not None and not math.isclose(given_dt, file_dt, rel_tol=1e-6):
        raise RecordError(path, None, f"dt = {given_dt!r} s was given but the record's time step is {file_dt:.9g} s")
    record = Record(name=name, dt=file_dt if file_dt is not None else given_dt,
                    acceleration=samples * UNITS[unit], source=str(path), credit=credit,
                    start_time=start + float(time_shift))
    record = replace(record, warnings=_plausibility(record, unit))
    factor = scale_factor(record, scale, target_pga, target_pga_g, target_sa, sa_period, sa_damping)
    return record.scaled(factor) if factor != 1.0 else record


def record_from_parameters(parameters: Mapping, records_dir: str | Path | None = None) -> Record:
    """The record ``ground_motion.fmu`` plays for these parameter values (FMI names, every one given).

    One mapping from the FMU's parameters to :func:`load_record`, used by the FMU and by the
    master's reference solver alike.
    """
    p = parameters
    return load_record(p["record"], fmt=p["format"], dt=float(p["dt"]) or None, units=p["units"],
                       scale=float(p["scale"]), target_pga=float(p["target_pga"]) or None,
                       time_shift=float(p["time_shift"]), records_dir=records_dir,
                       target_pga_g=float(p["target_pga_g"]) or None, target_sa=float(p["target_sa"]) or None,
                       sa_period=float(p["sa_period"]) or None, sa_damping=float(p["sa_damping"]))
