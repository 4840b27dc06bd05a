"""Sub-commands of ``uav-el``, one module each (see ``assurance.cli``)."""
