"""Geometry stage: the tube wall (and later mixers) built with gmsh, split into thermal wall zones."""

from .build import build
from .export import picture

__all__ = ["build", "picture"]
