# Resolved intra-particle conduction (issue 13, the ParScale model): wall heat of a wall-heated bed,
# uniform against resolved particles, over the Biot number; and the two scenes of thermal.intraparticle: auto.


rule intraparticle_study:
    output:
        sweep=report("results/intraparticle_study/{key}/biot_sweep.csv", caption="../report/intraparticle_study.rst", category="Intra-particle conduction"),
        figure=report("results/intraparticle_study/{key}/biot_sweep.png", caption="../report/intraparticle_study.rst", category="Intra-particle conduction"),
        scenes=report("results/intraparticle_study/{key}/auto_scenes.csv", caption="../report/intraparticle_auto.rst", category="Intra-particle conduction"),
        summary="results/intraparticle_study/{key}/summary.json",
    params:
        spec=spec_json,
        io=io_json,
    threads: 2
    log:
        "results/intraparticle_study/{key}/study.log",
    run:
        run_stage("intraparticle_study", params, log)
