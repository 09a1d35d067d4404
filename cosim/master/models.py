"""The physics objects an instance of a scene stands for, built from its parameter values.

The slaves build the same objects in ``initialize()`` from the same values (the scene's, else
the FMU's defaults: :meth:`cosim.master.scene.InstanceSpec.value`); the master needs them for
what it reports without asking an FMU (a building's periods, the record a run plays), to prove
that a gap stays open over a long step (:mod:`cosim.master.gap_bound`), and the monolithic
reference solver (:func:`cosim.peers.reference.scene_inputs`) for its equations.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from fmu_src.contact_laws import ContactLaw, law_for
from fmu_src.ground_records import Record, record_from_parameters
from fmu_src.shear_building import ShearBuilding

from .interface import parameter_defaults
from .names import element_name

if TYPE_CHECKING:
    from .scene import InstanceSpec


def shear_building(spec: "InstanceSpec") -> ShearBuilding:
    """The linear shear building of a ``building.fmu`` instance (stiffnesses scaled to ``T1``
    when ``T1 > 0``); ValueError as the FMU would refuse it."""
    n = int(spec.value("n_storeys"))
    floors = range(1, n + 1)
    masses = [float(spec.value(element_name("m", i))) for i in floors]
    stiffnesses = [float(spec.value(element_name("k", i))) for i in floors]
    T1, zeta, damping = float(spec.value("T1")), float(spec.value("zeta")), spec.value("damping")
    if T1 > 0.0:
        return ShearBuilding.from_period(T1, masses, stiffnesses, zeta, damping)
    return ShearBuilding(masses, stiffnesses, zeta, damping)


def storeys_are_linear(spec: "InstanceSpec") -> bool:
    """True if every storey of the instance is linear elastic (``hysteresis = "linear"``, or an
    FMU without that parameter)."""
    try:
        return spec.value("hysteresis") == "linear"
    except KeyError:
        return True


def initial_state(spec: "InstanceSpec") -> tuple[np.ndarray, np.ndarray]:
    """Initial floor displacements (m) and velocities (m/s) of a ``building.fmu`` instance."""
    floors = range(1, int(spec.value("n_storeys")) + 1)
    return (np.array([float(spec.value(element_name("x0", i))) for i in floors]),
            np.array([float(spec.value(element_name("v0", i))) for i in floors]))


def ground_record(spec: "InstanceSpec") -> Record:
    """The record a ``ground_motion.fmu`` instance plays (scaled as its parameters say)."""
    return record_from_parameters({**parameter_defaults(spec.fmu), **spec.parameters})


def contact_law(spec: "InstanceSpec") -> ContactLaw:
    """The contact law of a ``pounding.fmu`` instance."""
    p = spec.value
    return law_for(p("model"), float(p("k")), float(p("n")), float(p("m1")), float(p("m2")), float(p("CR")),
                   float(p("zeta")))
