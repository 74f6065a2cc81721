"""LIGGGHTS deck templates (package data) rendered by :mod:`dpht.liggghts`.

Placeholders are ``@{name}``; ``${name}`` is left for LIGGGHTS' own variables.
"""
