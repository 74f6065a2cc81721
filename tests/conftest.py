"""The order the test files are handed to pytest-xdist's workers (`make test`: ``-n 2 --dist loadfile``).

Each file runs whole on one worker, and a worker takes the next file in the queue when it is nearly
done with its own. pytest-xdist queues the files with the most tests first, which put the few long
end-to-end files (one to five tests of minutes each: the fault injection, the SLURM cluster, the
interruptions) at the end of the queue, where a worker drawing one of them last runs on alone for
minutes after the other has finished. Longest first instead (the usual rule for balancing jobs over
machines): the files of FIRST, then the others as pytest-xdist would queue them (most tests first).
The seconds are rounded from ``--durations`` of whole-suite runs (2 workers, numba cache warm); they
only set the order, so they need updating only when a file's place in it changes.
"""

# Longest first, with the seconds each file took (rounded). test_slurm.py goes before the slightly
# longer test_faults.py: it starts its cluster first, so its workflow reaches the thermal stage later
# than test_workflow.py's, while the fault test's (the same tiny workflow from the same start) would
# reach it at the same moment, and in a fresh clone both would compile the same numba kernels at once.
FIRST = (
    "test_workflow.py",  # 300 s
    "test_slurm.py",  # 205 s
    "test_faults.py",  # 215 s
    "test_benchmarks.py",  # 180 s (two benchmarks run LIGGGHTS at their tiny size)
    "test_liggghts.py",  # 170 s
    "test_chain.py",  # 130 s (the tiny chain's DEM runs and segments)
    "test_interrupts.py",  # 110 s
    "test_workflow_errors.py",  # 105 s (the tiny scene's DEM and screening with another seed)
    "test_watkins.py",  # 90 s
    "test_accuracy.py",  # 80 s
    "test_thermal_resume.py",  # 45 s (8 runs each resumed from every checkpoint; measured alone at load 6)
    "test_messages.py",  # 45 s (two snakemake dry runs among 460 cases)
    "test_verification.py",  # 35 s
    "test_quick.py",  # 35 s
    "test_packing.py",  # 30 s
    "test_properties.py",  # 30 s
    "test_rdf_build.py",  # 30 s
    "test_radiation_study.py",  # 25 s
    "test_thermal_stage.py",  # 22 s
)


def pytest_configure(config):
    # pytest-xdist's own reordering (most tests first) would undo the order set below.
    if hasattr(config.option, "loadscopereorder"):
        config.option.loadscopereorder = False


def pytest_collection_modifyitems(items):
    files = {}
    for item in items:
        files.setdefault(item.path.name, []).append(item)
    # sorted() is stable: files of equal weight keep the collection's order.
    order = sorted(files, key=lambda name: (FIRST.index(name) if name in FIRST else len(FIRST), -len(files[name])))
    items[:] = [item for name in order for item in files[name]]
