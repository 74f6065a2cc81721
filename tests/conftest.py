"""The order the test files are handed to pytest-xdist's workers (`make test`: ``-n 2 --dist loadfile``).

Each file runs whole on one worker, and a worker takes the next file in the queue when it is nearly
done with its own. pytest-xdist queues the files with the most tests first, which put the few long
end-to-end files (one to five tests of minutes each: the fault injection, the SLURM cluster, the
interruptions) last, where one of them ran on alone after the other worker had finished. Longest
first instead (the classic rule for balancing jobs over machines): the files below, in their
measured order, then the others as pytest-xdist would queue them (most tests first). Seconds
measured with ``pytest --durations=0`` in a whole-suite run (warm numba cache, 2 workers); they only
set the order, so they need updating only when a file's place in it changes.
"""

SECONDS = {
    "test_workflow.py": 330,
    "test_faults.py": 215,
    "test_slurm.py": 205,
    "test_liggghts.py": 150,
    "test_interrupts.py": 110,
    "test_watkins.py": 70,
    "test_accuracy.py": 70,
    "test_workflow_errors.py": 40,
    "test_quick.py": 35,
    "test_verification.py": 35,
}


def pytest_configure(config):
    # pytest-xdist's own reordering (most tests first) would undo the order set below.
    if hasattr(config.option, "loadscopereorder"):
        config.option.loadscopereorder = False


def pytest_collection_modifyitems(items):
    files = {}
    for item in items:
        files.setdefault(item.path.name, []).append(item)
    # sorted() is stable: files of equal weight keep the collection's order.
    order = sorted(files, key=lambda name: (-SECONDS.get(name, 0), -len(files[name])))
    items[:] = [item for name in order for item in files[name]]
