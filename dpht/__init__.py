"""DPHT: heat transfer in dense granular flows from DEM particle positions.

The thermal method follows Johnson, Tarı & Baker (2021), "Modeling heat exchangers with an open
source DEM-based code for granular flows", Solar Energy 228: 374-386 (cited as "DPHT paper, Eq. N").
All quantities are SI (m, s, K, W, J) unless a docstring says otherwise.
"""

__version__ = "0.1.0"

import os

# numba's threading layer: OpenMP (libgomp). numba prefers TBB when its library is installed, as
# Debian's VTK (a LIGGGHTS dependency) installs it; on a loaded machine a stage process was seen
# spinning in TBB's shutdown for minutes after its work was done. Set the variable to override.
os.environ.setdefault("NUMBA_THREADING_LAYER", "omp")
