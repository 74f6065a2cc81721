# The studies (registry dpht/studies/): one rule per study, named as the study, writing its outputs
# into results/<run>/studies/<study>/, and one rule per keyed stage of a study (cached by content
# in results/<stage>/<key>/). Made from the registry: a new study needs no edit here. A study the
# config's `studies` lists is part of `all`; any other runs when its rule is named as a target
# (`snakemake --cores 2 accuracy`), planned then (dpht.plan.Plan.study).


def _study_input(name):
    return lambda wildcards: dict(PLAN.study(name).inputs)


def _study_spec(name):
    return lambda wildcards: PLAN.study(name).spec_json()


def _study_report(name, output):
    return lambda wildcards: PLAN.study_report(name, output)


for _stage in studies.KEYED.values():

    rule:
        name:
            _stage.name
        input:
            unpack(lambda w: PLAN.keyed_inputs(w.key)),
        output:
            **{name: paths.stage_pattern(_stage.name, file) for name, file in _stage.outputs.items()},
        params:
            spec=spec_json,
            io=io_json,
            stage=_stage.name,
        threads: _stage.threads
        log:
            paths.stage_pattern(_stage.name, "stage.log"),
        run:
            run_stage(params.stage, params, log)


for _study in studies.STUDIES.values():

    rule:
        name:
            _study.name
        input:
            unpack(_study_input(_study.name)),
        output:
            **{
                name: report_item(file, out.caption, _study_report(_study.name, name)) if out.caption else file
                for (name, out), file in zip(_study.outputs.items(), _study.files(RUN).values())
            },
        params:
            spec=_study_spec(_study.name),
            io=io_json,
            stage=_study.name,
        threads: _study.threads
        localrule: True
        log:
            run_path(paths.STUDY, study=_study.name, file=f"{_study.name}.log"),
        run:
            run_stage(params.stage, params, log)
