# Config validation and the plan of stage runs (dpht.plan: stage keys, rule inputs, parameters and
# targets, unit-tested in tests/workflow/test_workflow.py), and how a rule calls a stage.

import json
import os
import subprocess
import sys

from dpht import cost, paths, studies
from dpht.config import VARIANT_NAME
from dpht.errors import USER_ERRORS
from dpht import integrity
from dpht.plan import COMPARISON, FIGURES, from_workflow
from dpht.stages import failure
from dpht.util import processes
from snakemake.exceptions import IncompleteCheckpointException, WorkflowError
from snakemake.io import checkpoint_target


wildcard_constraints:
    key="[0-9a-f]{12}",
    variant=VARIANT_NAME,


# The config files are read again here, so that errors name the file and line that set a key, and
# everything the config asks for is checked before the first job (dpht.preflight).
try:
    PLAN = from_workflow(config, workflow.configfiles, workflow.overwrite_configfiles, workflow.config_settings.config)
except USER_ERRORS as err:
    sys.exit(f"dpht: error: {err}")
RUN = PLAN.name  # this run's folder, results/<RUN>/ (dpht.paths)


def run_path(pattern, **fields):
    """A path of this run's folder (dpht.paths), other fields left as wildcards."""
    return pattern.format(run=RUN, **{"variant": "{variant}", **fields})

# Before Snakemake looks at the outputs: a missing, cut-short or altered result of an earlier run
# (by the manifests the stages write, dpht.integrity) is moved aside and made a target (rule all),
# so that its stage runs again, and everything downstream. A dry run only reports. Not in the job
# processes of remote executors. Files whose stat is as recorded are not hashed, unless DPHT_HASH_ALL=1.
REMADE, DAMAGE = (integrity.check(PLAN, dry_run=integrity.dry_run(workflow), hash_all=integrity.hash_all())
                  if workflow.is_main_process else ([], []))
for warning in DAMAGE:
    print(warning, file=sys.stderr)

# Stage processes stop when this snakemake process is gone (dpht.util.processes.watch_workflow).
os.environ[processes.WORKFLOW_PID] = str(os.getpid())


# One overall progress line with an ETA (dpht.cost.Overall) when the run starts, when each stage job
# starts and ends, and at its end; from the jobs Snakemake will run, in this process (the stage jobs
# run in its threads: profiles/default), not in the job processes of remote executors.
OVERALL = []


def overall(event=""):
    if OVERALL:
        OVERALL[0].report(event)


onstart:
    # SIGINT or SIGTERM sent to snakemake alone (kill -INT, a scheduler) reaches the stages too,
    # which stop LIGGGHTS; Snakemake itself would wait for a running DEM to finish.
    processes.forward_signals()
    try:
        cores = workflow.cores
    except WorkflowError:  # no --cores (a cluster's --jobs): no wall time to estimate
        cores = None
    if cores:
        jobs = workflow.dag.needrun_jobs()
        OVERALL.append(cost.Overall.of_jobs(PLAN, ((job.rule.name, job.wildcards.get("key"), list(job.output)) for job in jobs),
                                            cores))  # fmt: skip
        print(OVERALL[0].explain(), file=sys.stderr)
        overall("start")


onsuccess:
    overall("end")


def report_item(file, caption, item):
    """``file`` flagged for ``snakemake --report`` with its caption (workflow/report/<caption>.rst)
    and its place there: ``item(wildcards)``, a dpht.plan.ReportItem (category, subcategory and
    labels naming the figure, the variant and the study), read from the plan when the report is built."""

    def field(name):
        return lambda wildcards: getattr(item(wildcards), name)

    return report(file, caption=f"../report/{caption}.rst", category=field("category"), subcategory=field("subcategory"),
                  labels=field("labels"))  # fmt: skip


def spec_json(wildcards):
    return PLAN.spec_json(wildcards.key)


def screened(key):
    """The decisions of screening run ``key`` (once its checkpoint has run; Snakemake plans the
    thermal stage's inputs again then)."""
    job = checkpoints.screening.get(key=key)
    try:
        with open(job.output.screening) as f:
            return json.load(f)["decisions"]
    except (ValueError, KeyError):
        # Damaged: a dry run leaves it in place (a run has moved it aside), so it is planned as not
        # yet screened, as Snakemake plans a checkpoint whose output is missing.
        raise IncompleteCheckpointException(job.rule, checkpoint_target(job.output.screening)) from None


def io_json(wildcards, input, output, threads, resources):
    # A function of threads and resources, so Snakemake leaves it out of its params rerun trigger.
    io = {"input": dict(input.items()), "output": dict(output.items()), "threads": threads}
    if "mpi" in resources.keys():  # MPI rules: the launcher and the rank count
        io["mpi"] = {"launcher": resources.mpi, "ranks": resources.tasks}
    return json.dumps(io)


def stage(name):
    """Shell command running one stage in its own process (progress goes to the log too, errors to
    the log only: run_stage shows them)."""
    return (f"{sys.executable} -m dpht stage {name} --spec {{params.spec:q}} --io {{params.io:q}} --log {{log:q}} "
            "--errors-to-log-only")


def run_stage(name, params, log):
    """A rule's run: block: stage ``name`` in its own process, as shell: would run it (Snakemake
    tracks and stops it the same way). If it fails, the error Snakemake shows is the stage's own
    message, once: a shell: rule would bury it under the whole command line and its JSON."""
    overall(f"{name} started")
    try:
        shell(stage(name))
    except subprocess.CalledProcessError as err:
        raise failure(name, log[0], err.returncode) from None
    overall(f"{name} done")
