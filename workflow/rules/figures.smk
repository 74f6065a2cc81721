# Figures per design variant (pyvista cross-section, heat flux along the tube, ...) and the
# comparison of variants; each PNG is captioned for `snakemake --report`.

FIGURES = ["cross_section", "wall_heat_flux", "wall_heat_history", "temperature_profiles", "htc_curves"]


def figures_spec(wildcards):
    cfg = KEYS[wildcards.variant]["config"]
    d = cfg["particles"]["diameter"]
    orifice = cfg["geometry"]["tube"]["orifice_height"]
    return json.dumps(
        {
            "window": cfg["figures"]["steady_window"],
            "heated_zones": sorted(z for z, bc in cfg["thermal"]["walls"].items() if bc != "adiabatic"),
            "radial_band": [orifice, orifice + 2 * d],
            "htc": {
                "radius": d / 2,
                "k_solid": cfg["particles"]["conductivity"],
                "solid_fraction": cfg["thermal"]["solid_fraction"],
                "gas": cfg["thermal"]["gas"],
            },
        },
        sort_keys=True,
    )


rule figures:
    input:
        positions=lambda w: stage_file(w.variant, "dem", "positions.h5"),
        walls=lambda w: stage_file(w.variant, "geometry", "walls.h5"),
        thermal=lambda w: stage_file(w.variant, "thermal", "thermal.h5"),
    output:
        **{
            name: report(
                f"results/{{variant}}/figures/{name}.png",
                caption=f"../report/{name}.rst",
                category="{variant}",
            )
            for name in FIGURES
        },
    params:
        spec=figures_spec,
        io=io_json,
    log:
        "results/{variant}/figures/figures.log",
    shell:
        stage("figures")


rule variant_summary:
    input:
        geometry=lambda w: stage_file(w.variant, "geometry", "geometry.json"),
        dem=lambda w: stage_file(w.variant, "dem", "summary.json"),
        thermal=lambda w: stage_file(w.variant, "thermal", "summary.json"),
    output:
        "results/{variant}/summary.json",
    params:
        stage_keys=lambda w: {k: v for k, v in KEYS[w.variant].items() if k != "config"},
    run:
        summary = {"stage_keys": params.stage_keys}
        for name, file in input.items():
            with open(file) as f:
                summary[name] = json.load(f)
        with open(output[0], "w") as f:
            json.dump(summary, f, indent=2, sort_keys=True)


rule compare_variants:
    input:
        **{f"thermal_{v}": stage_file(v, "thermal", "thermal.h5") for v in VARIANTS},
        **{f"walls_{v}": stage_file(v, "geometry", "walls.h5") for v in VARIANTS},
        **{f"positions_{v}": stage_file(v, "dem", "positions.h5") for v in VARIANTS},
    output:
        comparison=report("results/comparison/variants.png", caption="../report/compare_variants.rst", category="Comparison"),
        cross_sections=report(
            "results/comparison/cross_sections.png", caption="../report/compare_cross_sections.rst", category="Comparison"
        ),
    params:
        spec=lambda w: json.dumps({"variants": VARIANTS, "window": CONFIG["figures"]["steady_window"]}),
        io=io_json,
    log:
        "results/comparison/compare.log",
    shell:
        stage("compare")
