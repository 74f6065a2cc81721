# gmsh: tube (+ mixers) -> zone STLs for LIGGGHTS and the wall-element table for the thermal stage.


rule geometry:
    output:
        walls=paths.stage_pattern("geometry", "walls.h5"),
        summary=paths.stage_pattern("geometry", "geometry.json"),
        picture=report(
            paths.stage_pattern("geometry", "geometry.png"), caption="../report/geometry.rst", category="Geometry"
        ),
    params:
        spec=spec_json,
        io=io_json,
    log:
        paths.stage_pattern("geometry", "geometry.log"),
    run:
        run_stage("geometry", params, log)
