"""Applications built on the master and the peers: studies, calibration, accuracy study, report."""
