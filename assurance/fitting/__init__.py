"""Fitting what flies and auditing it: the network, the learned monitor, the out-of-domain gate, calibration."""
