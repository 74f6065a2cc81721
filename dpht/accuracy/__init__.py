"""The accuracy study (issue 15): what accuracy costs in wall time, knob by knob."""
