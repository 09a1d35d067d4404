"""The CR each contact law achieves with its published constant (``docs/contact_models.md``).

    pounding-cosim cr-table --n 1 1.5

By scale invariance one impact of two free masses per cell (m = k = v = 1,
:func:`fmu_src.single_impact.simulate_impact`) gives the achieved CR of a law, a constant and
an exponent.
"""
from __future__ import annotations

from fmu_src.contact_laws import LAWS, ContactLaw
from fmu_src.single_impact import simulate_impact


def cr_table(crs=(0.1, 0.2, 0.4, 0.65, 0.8, 0.9, 0.95), ns=(1.5,), rtol: float = 1e-10) -> str:
    """Markdown table of the CR each model achieves with its published constant.

    Rows: models (plus ``crvk (printed)`` with the seed's Eq 3.9 constant); columns: target CR.
    By scale invariance one impact per cell (m = k = v = 1) is enough.
    """
    lines = []
    for n in ns:
        lines.append(f"\nAchieved CR with the published constant, n = {n:g}\n")
        lines.append("| model | " + " | ".join(f"CR={c:g}" for c in crs) + " |")
        lines.append("|---|" + "---|" * len(crs))
        rows = [(name, spec, lambda c, spec=spec: spec.constant(c, n)) for name, spec in LAWS.items()]
        # a law whose constant the seed paper prints differently gets a second row with it
        rows += [(f"{name} (printed constant)", spec, spec.printed) for name, spec in LAWS.items() if spec.printed]
        for name, spec, zeta_of in rows:
            model = spec.name
            cells = []
            for c in crs:
                law = ContactLaw(model, 1.0, n, 1.0, zeta_of(c))
                cells.append(f"{simulate_impact(law, 1.0, rtol=rtol).achieved_CR:.4f}")
            lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return "\n".join(lines)
