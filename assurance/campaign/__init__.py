"""Campaigns: perturbations, the task grid, judging candidates against ground truth, readouts and their integrity."""
