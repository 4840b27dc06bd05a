"""In-service evidence: flight logs (``el.flight.flightlog``) compared with the certification run of their system.

``reader`` folds logs of any size in one bounded pass; ``compare`` measures the run's clean test frames and sets the
two side by side (drift tests, rates with intervals); ``spi`` judges the system file's ``[in_service]`` indicators and
names the claims a breach undermines; ``report`` writes and signs ``in-service.json`` and ``in-service.html``;
``assess`` runs them in order for ``uav-el in-service``; ``section`` reads a signed report for the evidence report.
"""
