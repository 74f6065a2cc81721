# Config validation, stage keys and the helpers every rule uses.
#
# Each stage's outputs live in a folder named by a hash of the parameters that stage depends on
# (results/<stage>/<key>/), so design variants share every stage they do not change, a changed
# parameter re-runs exactly the stages downstream of it, and earlier results are kept.

import json
import sys

from dpht import config as dpht_config
from dpht.errors import ConfigError

wildcard_constraints:
    key="[0-9a-f]{12}",
    variant="[A-Za-z0-9_.-]+",

try:
    CONFIG = dpht_config.validate(config, source=", ".join(map(str, workflow.configfiles)) or "config")
except ConfigError as err:
    sys.exit(f"dpht: error: {err}")

VARIANTS = list(CONFIG["variants"])
SPECS = {}  # stage key -> the stage's parameters
UPSTREAM = {}  # stage key -> keys of the stages it reads from, and other per-run settings
KEYS = {}  # variant -> {stage: key}


def _register(spec, **upstream):
    key = dpht_config.digest({"spec": spec, "upstream": upstream})
    SPECS[key] = spec
    UPSTREAM[key] = upstream
    return key


for _name in VARIANTS:
    _cfg = dpht_config.variant(CONFIG, _name)
    _geometry = _register(dpht_config.geometry_spec(_cfg))
    _dem = _register(dpht_config.dem_spec(_cfg), geometry=_geometry)
    _pfp = _register(dpht_config.htc_spec(_cfg, "pfp"))
    _pfw = _register(dpht_config.htc_spec(_cfg, "pfw"))
    _rdf = dpht_config.rdf_spec(_cfg)
    _rdf = _register(_rdf) if _rdf is not None else None
    _thermal = _register(dpht_config.thermal_spec(_cfg), geometry=_geometry, dem=_dem, pfp=_pfp, pfw=_pfw, rdf=_rdf)
    # Not part of the key: ranks and the mass-flow check do not change the DEM result.
    UPSTREAM[_dem]["ranks"] = _cfg["dem"]["ranks"]
    UPSTREAM[_dem]["checks"] = dpht_config.dem_checks(_cfg)
    KEYS[_name] = {"geometry": _geometry, "dem": _dem, "pfp": _pfp, "pfw": _pfw, "rdf": _rdf, "thermal": _thermal, "config": _cfg}


if "radiation_study" in CONFIG:
    STUDY_RDF = _register(dpht_config.radiation_study_rdf_spec(CONFIG))
    STUDY = _register(CONFIG["radiation_study"], rdf=STUDY_RDF)


def spec_json(wildcards):
    return json.dumps(SPECS[wildcards.key], sort_keys=True)


def io_json(wildcards, input, output, threads, resources):
    # A function of threads and resources, so Snakemake leaves it out of its params rerun trigger.
    io = {"input": dict(input.items()), "output": dict(output.items()), "threads": threads}
    if "mpi" in resources.keys():  # MPI rules: the launcher and the rank count
        io["mpi"] = {"launcher": resources.mpi, "ranks": resources.tasks}
    return json.dumps(io)


def stage(name):
    """Shell command running one stage in its own process (progress and errors go to the log too)."""
    return f"{sys.executable} -m dpht stage {name} --spec {{params.spec:q}} --io {{params.io:q}} --log {{log:q}}"


def stage_file(variant, stage_name, file):
    """Output ``file`` of stage ``stage_name`` for a design variant (e.g. "dem", "positions.h5")."""
    return f"results/{stage_name}/{KEYS[variant][stage_name]}/{file}"


def htc_file(variant, kind):
    return f"tables/htc/{KEYS[variant][kind]}.h5"


def all_targets():
    """Every figure and summary of every variant, their comparison when there are several, and the
    radiation-model study when configured."""
    targets = [f"results/{v}/figures/{name}.png" for v in VARIANTS for name in FIGURES]
    targets += [f"results/{v}/summary.json" for v in VARIANTS]
    if len(VARIANTS) > 1:
        targets += ["results/comparison/variants.png", "results/comparison/cross_sections.png"]
    if "radiation_study" in CONFIG:
        targets.append(f"results/radiation_study/{STUDY}/fig9.png")
    return targets
