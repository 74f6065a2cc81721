# gmsh: tube (+ mixers) -> zone STLs for LIGGGHTS and the wall-element table for the thermal stage.


rule geometry:
    output:
        walls="results/geometry/{key}/walls.h5",
        summary="results/geometry/{key}/geometry.json",
        picture=report(
            "results/geometry/{key}/geometry.png", caption="../report/geometry.rst", category="Geometry"
        ),
    params:
        spec=spec_json,
        io=io_json,
    log:
        "results/geometry/{key}/geometry.log",
    run:
        run_stage("geometry", params, log)
