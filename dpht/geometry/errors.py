"""Errors of the geometry stage (dpht.geometry), which depends on nothing else in ``dpht``.

``dpht`` reports them like its own (see ``dpht.errors.USER_ERRORS``): one message, no traceback.
"""


class GeometryError(Exception):
    """Input the user can fix: a geometry config value, a wall table, a mesh."""


class GeometryConfigError(GeometryError):
    """A ``geometry`` config key or value is invalid; the message names the key."""


class GmshError(GeometryError):
    """gmsh failed or produced an unusable mesh."""
