"""Time-temperature superposition: synthetic Prony/WLF truth shifted back, real TA LIMS cooling series."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tissuemech import tts

REAL = Path("../shared/data/real")
LIMS = REAL / "ta_lims" / "ares_g2_frequency_sweep_tts.txt"

# truth: Prony spectrum at Tref (modes 1 us .. 100 s), WLF with the "universal" constants
TAUS = 10.0 ** np.arange(-6.0, 2.5, 1.0)
WEIGHTS = 1e6 * 10.0 ** (-0.35 * np.arange(TAUS.size))
G_EQ = 1e3
C1, C2, TREF = 8.86, 101.6, 40.0


def prony_moduli(omega):
    wt = np.outer(omega, TAUS)
    g1 = G_EQ + (WEIGHTS * wt ** 2 / (1 + wt ** 2)).sum(axis=1)
    g2 = (WEIGHTS * wt / (1 + wt ** 2)).sum(axis=1)
    return g1, g2


def synthetic_sweeps(temps, noise=0.01, seed=0, vertical=None):
    rng = np.random.default_rng(seed)
    omega = np.logspace(-1, 2, 16)    # 0.1-100 rad/s, as a typical sweep
    out = []
    for k, t in enumerate(temps):
        la = -C1 * (t - TREF) / (C2 + t - TREF)
        g1, g2 = prony_moduli(omega * 10 ** la)
        b = 1.0 if vertical is None else 10 ** vertical[k]
        g1 = g1 / b * np.exp(noise * rng.standard_normal(omega.size))   # reduced G_r = b_T G
        g2 = g2 / b * np.exp(noise * rng.standard_normal(omega.size))
        out.append(tts.Sweep(t, omega, g1, g2, f"T{t:g}"))
    return out


def test_synthetic_wlf_truth_is_shifted_back():
    temps = np.arange(0.0, 101.0, 10.0)
    res = tts.shift_factors(synthetic_sweeps(temps), t_ref_c=TREF)
    truth = tts.wlf_log_aT(temps, C1, C2, TREF)
    assert res.t_ref_c == TREF
    assert np.all(np.isfinite(res.log_aT))
    # 1 % noise on 16-point sweeps: every chained shift within 0.05 decades of the truth
    np.testing.assert_allclose(res.log_aT, truth, atol=0.05)
    # the stated uncertainty covers the error (|error| < 4 stderr + a small floor for interpolation bias)
    assert np.all(np.abs(res.log_aT - truth) <= 4 * res.log_aT_stderr + 0.02)
    wlf = tts.fit_wlf(res.temperatures_c, res.log_aT, res.log_aT_stderr, res.t_ref_c)
    assert wlf["success"]
    assert wlf["c1"] == pytest.approx(C1, rel=0.1)
    assert wlf["c2_k"] == pytest.approx(C2, rel=0.1)
    assert np.isfinite(wlf["c1_stderr"]) and wlf["c1_stderr"] > 0


def test_vertical_shift_recovers_a_known_modulus_factor():
    temps = np.arange(20.0, 61.0, 10.0)
    vert = 0.02 * (temps - TREF) / 10.0          # known log bT
    res = tts.shift_factors(synthetic_sweeps(temps, noise=0.003, vertical=vert), t_ref_c=TREF, vertical=True)
    np.testing.assert_allclose(res.log_bT, vert, atol=0.01)
    np.testing.assert_allclose(res.log_aT, tts.wlf_log_aT(temps, C1, C2, TREF), atol=0.06)


def test_arrhenius_fit_recovers_activation_energy():
    temps = np.arange(20.0, 81.0, 10.0)
    la = tts.arrhenius_log_aT(temps, 80e3, 50.0)
    fit = tts.fit_arrhenius(temps, la, np.full(temps.size, 0.01), 50.0)
    assert fit["ea_j_per_mol"] == pytest.approx(80e3, rel=1e-4)
    # hand check of the formula at 20 degC: 80e3/(8.314462618 ln10) (1/293.15 - 1/323.15) = 1.3233
    assert la[0] == pytest.approx(1.3233, abs=1e-3)


def test_mastercurve_predicts_a_held_out_temperature():
    temps = np.arange(0.0, 101.0, 10.0)
    sw = synthetic_sweeps(temps)
    held = 5                                      # 50 degC
    train = [s for k, s in enumerate(sw) if k != held]
    res = tts.shift_factors(train, t_ref_c=TREF)
    wlf = tts.fit_wlf(res.temperatures_c, res.log_aT, res.log_aT_stderr, res.t_ref_c)
    la = tts.wlf_log_aT(temps[held], wlf["c1"], wlf["c2_k"], res.t_ref_c)
    mx, my = tts.mastercurve(sorted(train, key=lambda s: s.temperature_c), res.log_aT)
    pred = tts.predict_from_mastercurve(mx, my, sw[held].log_w, la)
    err = pred - sw[held].log_g
    assert np.isfinite(err).all()
    assert np.sqrt(np.mean(err ** 2)) < 0.02      # decades: ~ the 1 % noise (0.0043 decades) + shift error


def test_too_few_sweeps_raise():
    with pytest.raises(ValueError, match=">= 2 temperatures"):
        tts.shift_factors(synthetic_sweeps([40.0]))


def test_run_tts_writes_the_pipeline_scope(tmp_path):
    """The pipeline's TTS scope end to end on canonical run files: tts.nc, the WLF card, its *TRS block, the figure."""
    import json

    from tissuemech.canonical import make_run_dataset, read_netcdf, write_netcdf
    from tissuemech.diagnosis.temperature import leave_one_temperature_out

    temps = np.arange(20.0, 61.0, 10.0)
    for k, sw in enumerate(synthetic_sweeps(temps, noise=0.003)):
        run = make_run_dataset({"angular_frequency": sw.omega, "storage_modulus": sw.storage,
                                "loss_modulus": sw.loss, "temperature": np.full(sw.omega.size, sw.temperature_c)},
                               {"test": "frequency_sweep", "run": f"s_{k}", "specimen": "s", "sample": "a",
                                "order": k + 1})
        write_netcdf(run, tmp_path / "runs" / f"s_{k}.nc")
    out = {name: tmp_path / name for name in ("tts.nc", "card.json", "card.inp")}
    tts.run_tts(tmp_path / "runs", *out.values(), dataset="synthetic", t_ref_c=TREF,   # figure: built below
                held_out=leave_one_temperature_out)
    ds = read_netcdf(out["tts.nc"])
    np.testing.assert_allclose(ds["temperature_c"], temps)
    assert np.all(np.isfinite(ds["shift_factor"])) and ds.attrs["n_shifted"] == 5
    np.testing.assert_allclose(ds["log_aT"], tts.wlf_log_aT(temps, C1, C2, TREF), atol=0.03)
    # each temperature predicted from the others' mastercurve: near the noise, far better than unshifted
    assert ds.attrs["held_out_rms_decades"] < 0.02 < ds.attrs["held_out_rms_unshifted_decades"]
    assert np.isfinite(ds["held_out_rms"].values).sum() == ds.attrs["held_out_folds"] >= 3
    card = json.loads(out["card.json"].read_text())
    assert card["shift_function"] == "WLF" and card["t_ref_c"] == TREF
    assert card["wlf"]["c1_stderr"] > 0 and card["valid_range"]["temperature_c"] == [20.0, 60.0]
    # Abaqus: *TRS, DEFINITION=WLF with the data line theta_0, C1, C2
    lines = [ln for ln in out["card.inp"].read_text().splitlines() if not ln.startswith("**")]
    assert lines[0] == "*TRS, DEFINITION=WLF"
    np.testing.assert_allclose([float(v) for v in lines[1].split(",")], [TREF, card["wlf"]["c1"], card["wlf"]["c2_k"]],
                               rtol=1e-6)
    # the mastercurve figure (built, not rendered: saving it costs seconds): reduced moduli + shift function
    from tissuemech.plots import figure_mastercurve

    fig = figure_mastercurve(ds)
    assert len(fig.axes) == 3                       # mastercurve, shift function, temperature colour bar
    assert len(fig.axes[1].get_lines()) >= 2        # WLF and Arrhenius curves beside the shift factors


@pytest.mark.skipif(not LIMS.exists(), reason="real data (../shared/data/real) absent")
def test_real_lims_cooling_series_every_temperature_shifted(repo_root):
    """Through the pipeline descriptor (config/external/ta_lims): its blocks and nominal temperatures, the TTS
    scope's dataset and card."""
    import pandas as pd

    from tissuemech.io.dispatch import read_export

    blocks = {b.index: b for b in read_export(LIMS)}
    sheet = pd.read_csv(repo_root / "config" / "external" / "ta_lims" / "samples.csv")
    sweeps = []
    for row in sheet.itertuples():
        b = blocks[int(row.block)]
        t = float(np.nanmedian(b.data["temperature"]))
        assert t == pytest.approx(row.temperature_c, abs=0.5)     # the sheet's temperature is the step's own
        sweeps.append(tts.Sweep(t, b.data["angular_frequency"], b.data["storage_modulus"], b.data["loss_modulus"],
                                b.name))
    assert len(sweeps) == 20 and len(tts.distinct_temperatures(sheet["temperature_c"])) == 20
    ds = tts.tts_dataset(sweeps, t_ref_c=30.0)
    la, se = ds["log_aT"].values, ds["log_aT_stderr"].values
    assert ds.attrs["n_shifted"] == 20 and np.all(np.isfinite(la)) and np.all(np.isfinite(se))
    temps = ds["temperature_c"].values
    assert temps[0] == pytest.approx(-40, abs=1) and temps[-1] == pytest.approx(150, abs=1)
    assert np.all(np.diff(la) < 0)        # monotonic: colder is slower
    # RheoJAX's published factors on this series span +8.55 .. -3.98 (12.5 decades); reference-dependent,
    # so compare the span loosely and the ends within a decade
    assert la[0] - la[-1] == pytest.approx(8.55 + 3.98, abs=1.0)
    assert la[0] == pytest.approx(8.55, abs=1.0) and la[-1] == pytest.approx(-3.98, abs=1.0)
    card = tts.tts_card(ds, "ta_lims")
    assert card["shift_function"] == "WLF" and card["wlf"]["c1_stderr"] > 0 and card["wlf"]["c2_k_stderr"] > 0
    assert card["abaqus_trs"].splitlines()[1] == "*TRS, DEFINITION=WLF"


def test_mastercurve_curve_shifts_each_sweep_and_drops_what_the_shift_drops():
    """tts.mastercurve_curve: omega_r = a_T omega, G_r = b_T G, only positive moduli, unmatched temperatures out."""
    from tissuemech.fitting import Curve

    temps = np.array([20.0, 40.0, 60.0])
    sweeps = synthetic_sweeps(temps, noise=0.0)
    ds = tts.tts_dataset(sweeps, t_ref_c=TREF)
    curves = [Curve("frequency_sweep", f"temperature_c={s.temperature_c:g}", "oscillation",
                    {"angular_frequency": s.omega}, {"storage_modulus": s.storage.copy(), "loss_modulus": s.loss.copy()})
              for s in sweeps]
    curves[0].observed["loss_modulus"][3] = -1.0      # a negative G'' (as the real -40 degC sweep has): dropped
    stray = Curve("frequency_sweep", "temperature_c=90", "oscillation", {"angular_frequency": sweeps[0].omega},
                  {"storage_modulus": sweeps[0].storage, "loss_modulus": sweeps[0].loss})
    master, record = tts.mastercurve_curve(curves + [stray], [*temps, 90.0], ds)
    assert record["temperatures_c"] == [20.0, 40.0, 60.0] and list(record["left_out"]) == [stray.label]
    assert master.n_points == 3 * sweeps[0].omega.size - 1 and master.nominal == {"t_ref_c": TREF}
    w = master.inputs["angular_frequency"]
    assert np.all(np.diff(w) >= 0) and np.all(master.observed["loss_modulus"] > 0)
    # every reduced point lies on the truth at Tref (noise-free sweeps, shifts recovered by the criterion)
    g1, g2 = prony_moduli(w)
    np.testing.assert_allclose(master.observed["storage_modulus"], g1, rtol=0.05)
    np.testing.assert_allclose(master.observed["loss_modulus"], g2, rtol=0.05)
    span = np.log10(w.max() / w.min())
    assert span > np.log10(sweeps[0].omega.max() / sweeps[0].omega.min()) + 2   # wider than one sweep


def test_mastercurve_scope_replaces_the_plain_sweep_scope():
    """Sweeps at >= 2 temperatures are never fitted as one temperature: the mastercurve scope takes their place."""
    from tissuemech.scopes import MASTERCURVE_SCOPE, dataset_scopes

    cfg = {"models": {"frequency_sweep": ["prony4"], "stress_relaxation": ["sls1"]}}
    assert set(dataset_scopes(["frequency_sweep", "stress_relaxation"], cfg)) == {"frequency_sweep",
                                                                                  "stress_relaxation", "material"}
    scopes = dataset_scopes(["frequency_sweep", "stress_relaxation"], cfg, tts=True)
    assert set(scopes) == {MASTERCURVE_SCOPE, "stress_relaxation", "material"}
    # the material model takes the sweeps shifted to Tref too
    assert scopes["material"]["mastercurve"] and scopes["material"]["tests"] == ["stress_relaxation",
                                                                                 "frequency_sweep"]
    assert scopes[MASTERCURVE_SCOPE] == {"tests": ["frequency_sweep"], "models": ["prony4"], "mastercurve": True}
    cfg["models"][MASTERCURVE_SCOPE] = ["prony8", "fractional_zener"]
    assert dataset_scopes(["frequency_sweep"], cfg, tts=True)[MASTERCURVE_SCOPE]["models"] == ["prony8",
                                                                                              "fractional_zener"]


def test_fit_stage_fits_the_mastercurve_and_its_card_carries_the_shift(tmp_path):
    """run_fit_scope on a synthetic TTS dataset (3-mode Prony truth at Tref, WLF shifts): the one fit-stage path
    fits the reduced curve, writes its record, ranking and a card whose Abaqus block ends with *TRS."""
    import json

    from tissuemech.canonical import make_run_dataset, read_netcdf, write_netcdf
    from tissuemech.curves import average_runs, write_averages
    from tissuemech.fitting import FitRecord
    from tissuemech.stages import run_fit_scope

    taus, weights, g_eq = np.array([1e-4, 1e-2, 1.0]), np.array([5e5, 1e5, 2e4]), 1e3
    rng = np.random.default_rng(3)
    omega = np.logspace(-1, 2, 16)
    runs = []
    for k, t in enumerate([20.0, 30.0, 40.0, 50.0, 60.0]):
        wt = np.outer(omega * 10 ** (-C1 * (t - TREF) / (C2 + t - TREF)), taus)
        g1 = (g_eq + (weights * wt ** 2 / (1 + wt ** 2)).sum(axis=1)) * np.exp(0.003 * rng.standard_normal(16))
        g2 = (weights * wt / (1 + wt ** 2)).sum(axis=1) * np.exp(0.003 * rng.standard_normal(16))
        run = make_run_dataset({"angular_frequency": omega, "frequency": omega / (2 * np.pi), "storage_modulus": g1,
                                "loss_modulus": g2, "temperature": np.full(16, t)},
                               {"test": "frequency_sweep", "run": f"s_{k}", "specimen": "s", "sample": "a",
                                "order": k + 1, "temperature_c": t})
        write_netcdf(run, tmp_path / "runs" / f"s_{k}.nc")
        runs.append(run)
    tts.run_tts(tmp_path / "runs", tmp_path / "tts.nc", tmp_path / "c.json", tmp_path / "c.inp", t_ref_c=TREF)
    write_averages(average_runs(runs), tmp_path / "averages.nc")
    spec = {"tests": ["frequency_sweep"], "models": ["prony3", "prony4"], "mastercurve": True}
    with pytest.raises(ValueError, match="tts.nc"):
        run_fit_scope(tmp_path / "averages.nc", "mastercurve", spec, "torque", 0, 1, tmp_path / "f", tmp_path / "c",
                      tmp_path / "r.csv", poisson_ratio=0.45)
    table = run_fit_scope(tmp_path / "averages.nc", "mastercurve", spec, "torque", 0, 1, tmp_path / "fits",
                          tmp_path / "cards", tmp_path / "ranking.csv", poisson_ratio=0.45, dataset="synthetic",
                          tts_path=tmp_path / "tts.nc")
    # the truth has three modes: the four-mode fit has an undetermined mode and is not the recommendation
    by_model = table.set_index("model")
    assert bool(by_model.loc["prony3", "recommended"]) and not bool(by_model.loc["prony4", "recommended"])
    assert not bool(by_model.loc["prony4", "determined"]) and bool(by_model.loc["prony3", "determined"])
    rec = FitRecord.from_netcdf(tmp_path / "fits" / "prony3.nc")
    assert rec.curve_labels == [f"frequency_sweep|mastercurve Tref={TREF:g}degC"]
    assert float(by_model.loc["prony3", "nrmse"]) < 0.02             # the truth at Tref, recovered to the noise
    assert rec.ranges["omega_max_rad_per_s"] / rec.ranges["omega_min_rad_per_s"] > 1e5   # reduced: > one sweep
    card = json.loads((tmp_path / "cards" / "prony3.json").read_text())
    shift = card["time_temperature_shift"]
    assert shift["t_ref_c"] == pytest.approx(TREF) and shift["wlf"]["c1"] == pytest.approx(
        read_netcdf(tmp_path / "tts.nc").attrs["wlf_c1"])
    inp = (tmp_path / "cards" / "prony3.inp").read_text().splitlines()
    keywords = [ln for ln in inp if ln.startswith("*") and not ln.startswith("**")]
    assert keywords[-2:] == ["*VISCOELASTIC, TIME=PRONY", "*TRS, DEFINITION=WLF"]


def test_held_out_temperatures_are_predicted_within_their_noise():
    """Issue 15, done-when: every held-out interior temperature whose neighbours still overlap once it is removed is
    predicted from the others' mastercurve and WLF shift within its noise: the RMS log10 error of a point is at
    most 2.5x the per-point noise (1 % -> 0.0043 decades; the prediction error holds the held-out point's own
    noise and the mastercurve's, sqrt(2) x 0.0043 = 0.006, measured 0.006-0.008).

    Not covered, and said so: below 30 degC the sweeps are 2.5-3.6 decades apart once one is removed, more than
    or nearly the 3 decades one sweep spans, and the chained pair shift there is wrong by 0.15-1 decade (held-out
    errors 0.03 and 0.21 decades at 20 and 10 degC); the end temperatures are extrapolations (partly outside the
    others' mastercurve: NaN there)."""
    temps = np.arange(0.0, 101.0, 10.0)
    sw = synthetic_sweeps(temps)
    noise_decades = 0.01 / np.log(10)
    for held in range(3, temps.size - 1):
        if temps[held] == TREF:
            continue
        train = [s for k, s in enumerate(sw) if k != held]
        res = tts.shift_factors(train, t_ref_c=TREF)
        wlf = tts.fit_wlf(res.temperatures_c, res.log_aT, res.log_aT_stderr, res.t_ref_c)
        la = tts.wlf_log_aT(temps[held], wlf["c1"], wlf["c2_k"], res.t_ref_c)
        mx, my = tts.mastercurve(sorted(train, key=lambda s: s.temperature_c), res.log_aT)
        err = tts.predict_from_mastercurve(mx, my, sw[held].log_w, la) - sw[held].log_g
        assert np.isfinite(err).all(), temps[held]
        assert np.sqrt(np.mean(err ** 2)) < 2.5 * noise_decades, temps[held]
