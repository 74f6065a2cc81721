# The workflow is workflow/Snakefile (the Snakemake workflow catalog's layout). This file runs it
# from the repository's top folder without --snakefile: included as Snakemake includes a main
# Snakefile, so that its rule `all` stays the default target (an `include:` resets it).
workflow.include("workflow/Snakefile", overwrite_default_target=True)
