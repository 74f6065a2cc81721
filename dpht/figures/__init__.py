"""Figures: per-scene pictures and plots with their CSVs, variant comparisons, and the radiation
study's figure."""
