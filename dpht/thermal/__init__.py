"""The thermal stage: the model of one scene, compiled heat-rate kernels, neighbour and wall-distance
searches, time integration, and the stage loop with its HDF5/XDMF output."""
