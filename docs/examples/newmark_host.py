"""A host of pounding.fmu written from scratch: two one-storey buildings, Newmark's average
acceleration, fmpy.  Needs only numpy and fmpy (and the FMU's own requirements: numpy, scipy).

    python docs/examples/newmark_host.py path/to/pounding.fmu

The buildings (100 t each, periods 0.5 s and 1.0 s, 5 % damping) are pulled 5.5 cm apart and
released towards each other across a 1 cm gap; they pound five times in 4 s.
"""
import sys

import numpy as np
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave


def simulate(fmu_path, h=1e-3, t_end=4.0):
    # -- the structures: M x'' + C x' + K x = f, one degree of freedom per building --------
    m = np.array([1e5, 1e5])                               # kg
    w = 2 * np.pi / np.array([0.5, 1.0])                   # rad/s
    K = np.diag(m * w ** 2)                                # N/m, each storey to the ground
    C = np.diag(2 * 0.05 * m * w)                          # N s/m, 5 % damping
    x, v = np.array([-0.055, 0.055]), np.zeros(2)          # m, m/s: left building is body 1
    a = -(C @ v + K @ x) / m                               # m/s^2

    # -- the contact: parameters before leaving initialisation -----------------------------
    md = read_model_description(fmu_path)
    vr = {var.name: var.valueReference for var in md.modelVariables}
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=extract(fmu_path),
                    modelIdentifier=md.coSimulation.modelIdentifier, instanceName="contact")
    fmu.instantiate()
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    fmu.setReal([vr["gap"], vr["m1"], vr["m2"], vr["k"], vr["CR"]], [0.01, m[0], m[1], 2.75e9, 0.65])
    fmu.setString([vr["model"]], ["jankowski"])
    fmu.exitInitializationMode()

    # -- Newmark average acceleration, the contact force as the load at the end of the step -
    beta, gamma = 0.25, 0.5
    S = np.diag(m) + gamma * h * C + beta * h * h * K      # the same every step
    for k in range(int(round(t_end / h))):
        # Gauss-Seidel: the contact steps from the buildings' state at t ...
        fmu.setReal([vr["x1"], vr["v1"], vr["x2"], vr["v2"]], [x[0], v[0], x[1], v[1]])
        fmu.doStep(currentCommunicationPoint=k * h, communicationStepSize=h)
        F1, F2 = fmu.getReal([vr["F1"], vr["F2"]])         # N, the signed force on each body
        # ... then the buildings step with its force
        xt = x + h * v + (0.5 - beta) * h * h * a
        vt = v + (1 - gamma) * h * a
        a = np.linalg.solve(S, np.array([F1, F2]) - C @ vt - K @ xt)
        x, v = xt + beta * h * h * a, vt + gamma * h * a

    impacts = fmu.getInteger([vr["impacts"]])[0]
    F_max, E = fmu.getReal([vr["F_max"], vr["E_dissipated"]])  # N, J
    fmu.terminate()
    fmu.freeInstance()
    return {"impacts": impacts, "F_max": F_max, "E_dissipated": E, "x": x, "v": v}


if __name__ == "__main__":
    result = simulate(sys.argv[1])
    print(f"{result['impacts']} impacts, peak force {result['F_max']:.4g} N, "
          f"contact dissipated {result['E_dissipated']:.4g} J")
