"""Errors the user can act on. The CLI and the workflow print them without a traceback."""

from dpht.geometry.errors import GeometryError


class DPHTError(Exception):
    """An error caused by input (config, files, external tools), with a message that says what to fix."""


class ConfigError(DPHTError):
    """A config file, key or value is missing or invalid."""


class ExternalToolError(DPHTError):
    """An external program (LIGGGHTS, gmsh) failed; the message carries the tail of its log."""


# What the CLI and the stages report as one message: ours and the geometry package's.
USER_ERRORS = (DPHTError, GeometryError)
