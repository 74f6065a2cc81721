# The accuracy study (issue 15): every numerical knob of dpht/accuracy/knobs.py varied around its
# default; each setting is a scene of its own in the plan, so its stage runs are cached like a
# variant's. Not part of `all`: `snakemake --cores 2 accuracy_cost`.


rule accuracy_cost:
    input:
        unpack(lambda w: PLAN.accuracy_inputs()),
    output:
        table=report("results/accuracy/accuracy.csv", caption="../report/accuracy_table.rst", category="Accuracy and cost"),
        recommended=report("results/accuracy/recommended.csv", caption="../report/accuracy_recommended.rst", category="Accuracy and cost"),
        markdown="results/accuracy/recommended.md",
        convergence=report("results/accuracy/convergence.csv", caption="../report/accuracy_convergence.rst", category="Accuracy and cost"),
        knobs=report("results/accuracy/knobs.png", caption="../report/accuracy_knobs.rst", category="Accuracy and cost"),
        pareto=report("results/accuracy/pareto.png", caption="../report/accuracy_pareto.rst", category="Accuracy and cost"),
        convergence_figure=report("results/accuracy/convergence.png", caption="../report/accuracy_convergence.rst", category="Accuracy and cost"),
        summary="results/accuracy/summary.json",
    params:
        spec=lambda w: PLAN.accuracy_spec(),
        io=io_json,
    log:
        "results/accuracy/accuracy.log",
    run:
        run_stage("accuracy_cost", params, log)
