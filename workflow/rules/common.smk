# Config validation and the plan of stage runs (dpht.plan: stage keys, rule inputs, parameters and
# targets, unit-tested in tests/test_workflow.py), and how a rule calls a stage.

import json
import sys

from dpht import config as dpht_config
from dpht.errors import ConfigError
from dpht.plan import FIGURES, Plan


wildcard_constraints:
    key="[0-9a-f]{12}",
    variant="[A-Za-z0-9_.-]+",


try:
    PLAN = Plan(dpht_config.validate(config, source=", ".join(map(str, workflow.configfiles)) or "config"))
except ConfigError as err:
    sys.exit(f"dpht: error: {err}")


def spec_json(wildcards):
    return PLAN.spec_json(wildcards.key)


def io_json(wildcards, input, output, threads):
    return json.dumps({"input": dict(input.items()), "output": dict(output.items()), "threads": threads})


def stage(name):
    """Shell command running one stage in its own process (progress and errors go to the log too)."""
    return f"{sys.executable} -m dpht stage {name} --spec {{params.spec:q}} --io {{params.io:q}} --log {{log:q}}"
