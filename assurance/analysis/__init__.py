"""Analysis of campaign readouts: metrics, intervals, results tables, threshold sweeps and the paper's findings."""
