"""What every part of the report shares: the paper's inputs, the settings, the report being written."""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import matplotlib
import numpy as np

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from fmu_src.contact_laws import DAMPED_MODELS, ContactLaw, law_spec, published_label  # noqa: E402

COMMAND = "pounding-cosim report --out docs/reproduction"

# The paper's worked example (Sec. 3): effective mass 100 kg, "k = 6000 kN/sqrt(mm)" read as
# 6000 kN/mm^1.5 = 6000e3 N / (1e-3 m)^1.5, v = 10 m/s, CR = 0.4.
WE_M1 = WE_M2 = 200.0                      # kg: m1 m2 / (m1 + m2) = 100 kg
WE_K = 6000e3 / 1e-3 ** 1.5                # N/m^1.5 = 1.8974e11
WE_V = 10.0                                # m/s
WE_CR = 0.4
WE_N = 1.5
PAPER_WE_PEAK_N = 12000e3                  # "approximately 12000 kN"
PAPER_WE_DISSIPATED_J = 4189.0             # "4189 kN mm" (1 kN mm = 1 J)
PAPER_WE_GOLDSMITH_J = 4200.0
PAPER_WE_CR = 0.3527
PAPER_WE_CR_IMP, PAPER_WE_W_CR = 1.1903, 2.5269

# The "Katija et al. 2006" test: two 300 kg steel frames, 0.68 m/s.
EXP_M = 300.0                              # kg, each frame
EXP_V = 0.68                               # m/s
EXP_PEAK_MEASURED_N = 29.85e3
EXP_PEAK_NUMERICAL_N = 28.32e3
EXP_CR_ASSUMED = 0.6                       # the test gives no CR: an assumption, varied below

RECORDS = (("elcentro", "El Centro 1940"), ("kobe", "Kobe 1995"), ("sanfernando", "San Fernando 1971"),
           ("parkfield", "Parkfield 1966"))
FIG8_MODEL = "crvk"                        # the paper's proposed law, constant calibrated for each CR
G = 9.80665                                # m/s^2

#: Fig 1 / Fig 6 models plotted with their published constant (crvk: the printed Eq 3.9
#: constant); the labels are the contact law table's (``LawSpec.label``)
PUBLISHED_LABELS = {model: published_label(model) for model in DAMPED_MODELS}


def printed_zeta(model: str, CR: float, n: float = 1.5) -> float:
    """The damping constant as the seed paper prints it (the table's ``printed_constant``)."""
    return law_spec(model).printed_constant(CR, n)


@dataclass(frozen=True)
class Settings:
    """Resolution of the report (``quick``: reduced grids for the test)."""

    quick: bool
    cr_published: tuple = tuple(np.round(np.arange(0.05, 0.951, 0.05), 2))
    cr_calibrated: tuple = tuple(np.round(np.arange(0.05, 0.951, 0.15), 2))
    calibrated_models: tuple = DAMPED_MODELS
    fmu_subset: tuple = DAMPED_MODELS          # one FMU calibration per model, CRs spread over the grid
    exp_crs: tuple = (0.3, 0.45, 0.6, 0.75, 0.9)
    gaps: tuple = (0.0, 0.01, 0.02, 0.03, 0.05, 0.075, 0.10, 0.125, 0.15, 0.175, 0.20)
    crs: tuple = (0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9)
    pgas_g: tuple = (0.1, 0.2, 0.3, 0.5, 0.75, 1.0)
    stop_time: float | None = None             # s: None = whole records
    records: tuple = tuple(name for name, _ in RECORDS)

    @classmethod
    def make(cls, quick: bool) -> "Settings":
        if not quick:
            return cls(False)
        return cls(True, cr_published=(0.05, 0.35, 0.65, 0.95), cr_calibrated=(0.05, 0.95),
                   calibrated_models=("kelvin_voigt", "crvk"), fmu_subset=("jankowski", "crvk"), exp_crs=(0.5, 0.8),
                   gaps=(0.03, 0.1), crs=(0.4, 0.9), pgas_g=(0.3, 0.6), stop_time=6.0,
                   records=("kobe", "sanfernando"))


@dataclass
class Claim:
    where: str
    claim: str
    ours: str
    holds: str


@dataclass
class Report:
    settings: Settings
    out: Path
    sections: list[str] = field(default_factory=list)
    claims: list[Claim] = field(default_factory=list)
    figures: list[str] = field(default_factory=list)
    jobs: int = 1

    def figure(self, fig, name: str, caption: str) -> str:
        fig.tight_layout()
        fig.savefig(self.out / name, dpi=110)
        plt.close(fig)
        self.figures.append(name)
        return f"![{caption}]({name})\n\n*{caption}*\n"


def _kN(F: float) -> str:
    return f"{F / 1e3:,.0f} kN"


def _law(model, k, n, m, zeta):
    return ContactLaw(model, k, n, m, zeta if law_spec(model).damped else 0.0)
