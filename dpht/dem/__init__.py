"""The DEM stage: parameters and LIGGGHTS decks from the config, the resumable LIGGGHTS run, dumps
gathered into ``positions.h5``, the run report (mass flow, solid fraction) and the orifice
calibration."""
