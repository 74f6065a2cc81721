"""Studies that run the thermal model on scenes of their own (above the stages they reuse)."""
