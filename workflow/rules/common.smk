# Config validation and the plan of stage runs (dpht.plan: stage keys, rule inputs, parameters and
# targets, unit-tested in tests/test_workflow.py), and how a rule calls a stage.

import json
import os
import sys

from dpht import config as dpht_config
from dpht.errors import ConfigError
from dpht.integrity import set_aside_damaged
from dpht.plan import FIGURES, Plan
from dpht.util import processes


wildcard_constraints:
    key="[0-9a-f]{12}",
    variant="[A-Za-z0-9_.-]+",


try:
    PLAN = Plan(dpht_config.validate(config, source=", ".join(map(str, workflow.configfiles)) or "config"))
except ConfigError as err:
    sys.exit(f"dpht: error: {err}")

# Before Snakemake looks at the outputs: a damaged result of an earlier run is moved aside and
# made a target (rule all), so that its stage runs again (dpht.integrity). Not in the job
# processes of remote executors.
REMADE = set_aside_damaged(PLAN) if workflow.is_main_process else {}
for warning in REMADE.values():
    print(warning, file=sys.stderr)

# Stage processes stop when this snakemake process is gone (dpht.util.processes.watch_workflow).
os.environ[processes.WORKFLOW_PID] = str(os.getpid())


onstart:
    # SIGINT or SIGTERM sent to snakemake alone (kill -INT, a scheduler) reaches the stages too,
    # which stop LIGGGHTS; Snakemake itself would wait for a running DEM to finish.
    processes.forward_signals()


def spec_json(wildcards):
    return PLAN.spec_json(wildcards.key)


def io_json(wildcards, input, output, threads, resources):
    # A function of threads and resources, so Snakemake leaves it out of its params rerun trigger.
    io = {"input": dict(input.items()), "output": dict(output.items()), "threads": threads}
    if "mpi" in resources.keys():  # MPI rules: the launcher and the rank count
        io["mpi"] = {"launcher": resources.mpi, "ranks": resources.tasks}
    return json.dumps(io)


def stage(name):
    """Shell command running one stage in its own process (progress and errors go to the log too)."""
    return f"{sys.executable} -m dpht stage {name} --spec {{params.spec:q}} --io {{params.io:q}} --log {{log:q}}"
