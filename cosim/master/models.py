"""The physics a scene's instances run, built from their parameters the way the slaves build it.

The master needs a building's model to prove that a gap stays open over a long step
(:mod:`cosim.master.gap_bound`); the reference solver needs it to solve the scene itself
(:func:`cosim.peers.reference.scene_inputs`).  Both build it here, from the values the
instance has (:meth:`cosim.master.scene.InstanceSpec.value`: the scene's, else the FMU's
defaults), with the same :class:`fmu_src.shear_building.ShearBuilding` the building FMU's
``initialize()`` builds.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

from fmu_src.hysteresis import StoreyHysteresis
from fmu_src.shear_building import ShearBuilding

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


def storey_hysteresis(spec: "InstanceSpec") -> StoreyHysteresis:
    """The storey law of a ``building.fmu`` instance (:class:`fmu_src.hysteresis.StoreyHysteresis`),
    from the parameters the slave's ``initialize()`` reads."""
    floors = range(1, int(spec.value("n_storeys")) + 1)
    return StoreyHysteresis(
        str(spec.value("hysteresis")), [float(spec.value(element_name("Fy", i))) for i in floors],
        float(spec.value("alpha")), float(spec.value("bw_n")), float(spec.value("bw_beta")),
        float(spec.value("bw_gamma")))


def storeys_are_linear(spec: "InstanceSpec") -> bool:
    """True if every storey of the instance is linear elastic (``hysteresis = "linear"``, or an
    FMU without that parameter)."""
    try:
        return spec.value("hysteresis") == "linear"
    except KeyError:
        return True


def initial_state(spec: "InstanceSpec") -> tuple[list[float], list[float]]:
    """``(x0, v0)`` of the instance's floors (m, m/s, relative to the ground)."""
    n = int(spec.value("n_storeys"))
    return ([float(spec.value(element_name("x0", i))) for i in range(1, n + 1)],
            [float(spec.value(element_name("v0", i))) for i in range(1, n + 1)])
