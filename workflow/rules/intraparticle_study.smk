# Resolved intra-particle conduction (issue 13, the ParScale model): wall heat of a wall-heated bed,
# uniform against resolved particles, over the Biot number; the two scenes of thermal.intraparticle: auto;
# and the model's verification, the cooled sphere of ParScale's Table 1 against Crank's series.


rule intraparticle_study:
    output:
        sweep=report("results/intraparticle_study/{key}/biot_sweep.csv", caption="../report/intraparticle_study.rst", category="Intra-particle conduction"),
        figure=report("results/intraparticle_study/{key}/biot_sweep.png", caption="../report/intraparticle_study.rst", category="Intra-particle conduction"),
        scenes=report("results/intraparticle_study/{key}/auto_scenes.csv", caption="../report/intraparticle_auto.rst", category="Intra-particle conduction"),
        cooled=report("results/intraparticle_study/{key}/cooled_sphere.png", caption="../report/cooled_sphere.rst", category="Intra-particle conduction"),
        convergence=report("results/intraparticle_study/{key}/cooled_sphere_convergence.png", caption="../report/cooled_sphere_convergence.rst", category="Intra-particle conduction"),
        profiles="results/intraparticle_study/{key}/cooled_sphere.csv",
        convergence_table="results/intraparticle_study/{key}/cooled_sphere_convergence.csv",
        summary="results/intraparticle_study/{key}/summary.json",
    params:
        spec=spec_json,
        io=io_json,
    threads: 2
    log:
        "results/intraparticle_study/{key}/study.log",
    run:
        run_stage("intraparticle_study", params, log)
