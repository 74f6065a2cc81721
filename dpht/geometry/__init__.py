"""Geometry stage: the tube wall, its orifice plate and any mixers, built with gmsh and split into
thermal wall zones.

gmsh is imported inside the functions that build or mesh the solids, not by any module: the config
and the workflow's plan read the geometry (its dimensions, checks and wall sampling, no mesh) and
must not load gmsh to do so."""

from dpht.geometry.build import build
from dpht.geometry.export import picture

__all__ = ["build", "picture"]
