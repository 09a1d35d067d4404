"""Peers of the master: other ways to solve or run the same scene.

* :mod:`.reference`: the monolithic ``solve_ivp`` reference (the oracle of the accuracy study);
* :mod:`.opensees` (child process :mod:`.opensees_worker`): OpenSees, as practice solves it;
* :mod:`.ssp`: SSP 1.0 export and import; :mod:`.libcosim`: running an SSP system in libcosim.

Each imports the master (scenes, names) and ``fmu_src`` (physics), never an application.
"""
