"""The evidence report's packaged templates (Jinja2 ``*.j2`` and the stylesheet), a package only so that the wheel
carries them as package data: ``assurance.evidence.render`` finds this folder and renders them in its sandbox.
A folder given with ``uav-el evidence --templates DIR`` (or the system file's ``[report] templates``) overrides
them file by file."""
