"""Small utilities every stage uses: HDF5 checks, safe expressions, table interpolation, progress."""
