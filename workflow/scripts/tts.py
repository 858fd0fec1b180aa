"""Snakemake adapter: frequency-sweep runs at >= 2 temperatures -> tts.nc, shift-function card (+ *TRS), figure."""
from tissuemech.diagnosis.temperature import leave_one_temperature_out
from tissuemech.pipeline import job_log
from tissuemech.tts import run_tts

with job_log(snakemake.log[0], end_process=True) as log:
    out = snakemake.output
    ds = run_tts(snakemake.input.runs, out.tts, out.card, out.abaqus, out.figure, dataset=snakemake.wildcards.dataset,
                 t_ref_c=snakemake.params.t_ref_c, vertical=snakemake.params.vertical,
                 exclude_flagged=snakemake.params.exclude_flagged, held_out=leave_one_temperature_out)
    a = ds.attrs
    log.info("%d of %d temperatures shifted, Tref = %g degC; WLF C1 = %.4g +- %.2g, C2 = %.4g +- %.2g K; "
             "Arrhenius Ea = %.4g +- %.2g J/mol", a["n_shifted"], a["n_temperatures"], a["t_ref_c"],
             a.get("wlf_c1", float("nan")), a.get("wlf_c1_stderr", float("nan")), a.get("wlf_c2_k", float("nan")),
             a.get("wlf_c2_k_stderr", float("nan")), a.get("arrhenius_ea_j_per_mol", float("nan")),
             a.get("arrhenius_ea_j_per_mol_stderr", float("nan")))
