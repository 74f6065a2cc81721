# A design variant with a `chain` section runs as a chain of segments along its tube
# (docs/theory/chain.md, dpht/chain/): one segment job per segment in flow order, the thermal stage
# started from the hand-over field of the segment above and writing its own; their DEM runs (rule
# dem) are one per resolved shape and one for every slice. The chain's summary adds them up.


rule segment:
    input:
        unpack(lambda w: PLAN.thermal_inputs(w.key, screened)),
    output:
        thermal=paths.stage_pattern("segment", "thermal.h5"),
        xdmf=paths.stage_pattern("segment", "thermal.xdmf"),
        summary=paths.stage_pattern("segment", "summary.json"),
        handover=paths.stage_pattern("segment", "handover.h5"),
    params:
        spec=spec_json,
        io=io_json,
    threads: 2
    log:
        paths.stage_pattern("segment", "segment.log"),
    run:
        run_stage("segment", params, log)


rule chain_summary:
    input:
        unpack(lambda w: PLAN.chain_inputs(w.variant)),
    output:
        summary=run_path(paths.CHAIN),
    params:
        spec=lambda w: PLAN.chain_spec(w.variant),
        io=io_json,
    log:
        run_path(paths.CHAIN_LOG),
    run:
        run_stage("chain_summary", params, log)
