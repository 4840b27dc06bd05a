"""Data on disk in the UAVid layout (``ROOT/seqNN/{Images,Labels}``): reading and writing samples and label maps,
and the per-frame poses beside them. The lowest layer of the harness after its base modules: every data set a
campaign, a fit or a report reads goes through it, synthetic or real."""
