"""Emergency-landing flight code: segmentation, landing candidates, ranking, runtime monitors.

This package never imports ``assurance`` (the test harness).
"""

__version__ = "0.1.0"
