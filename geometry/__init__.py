"""Geometry stage: the tube wall, its orifice plate and any mixers, built with gmsh and split into
thermal wall zones."""

from geometry.build import build
from geometry.export import picture

__all__ = ["build", "picture"]
