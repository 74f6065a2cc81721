# gmsh: tube (+ mixers) -> zone STLs for LIGGGHTS and the wall-element table for the thermal stage.


rule geometry:
    output:
        walls=paths.stage_pattern("geometry", "walls.h5"),
        summary=paths.stage_pattern("geometry", "geometry.json"),
        picture=report_item(paths.stage_pattern("geometry", "geometry.png"), "geometry", lambda w: PLAN.geometry_report(w.key)),
    params:
        spec=spec_json,
        io=io_json,
    log:
        paths.stage_pattern("geometry", "geometry.log"),
    run:
        run_stage("geometry", params, log)
