"""Safety-assurance harness around the emergency-landing system: requirements, campaigns, evidence."""

__version__ = "0.1.0"
