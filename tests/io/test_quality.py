"""Point-level quality flags (issue 13, item 5): inertia, declared torque resolution, frequency-sweep points above
the same sample's LVE limit; not-testable reasons; exclusion from the averages the fits read; hollow markers."""
from __future__ import annotations

import math

import numpy as np
import pytest

from tissuemech.canonical import make_run_dataset, read_netcdf
from tissuemech.curves import average_runs, select_average
from tissuemech.io.dispatch import read_export
from tissuemech.io.ingest import ingest_dataset
from tissuemech.io.quality import (FLAG_VARIABLE, INERTIA_DOMINATED, OUTSIDE_LVE, TORQUE_BELOW_RESOLUTION,
                                   declared_torque_resolution, flag_runs, with_quality_flags)
from tissuemech.plots import figure_average

DEG = math.pi / 180
OMEGA = np.logspace(-1, 2, 10)  # rad/s


def sweep(test="frequency_sweep", specimen="s1", sample="a", raw_phase_deg=None, torque=None, strain=None, **attrs):
    n = OMEGA.size
    columns = {"angular_frequency": OMEGA, "storage_modulus": np.full(n, 1000.0), "loss_modulus": np.full(n, 100.0)}
    if raw_phase_deg is not None:
        columns["raw_phase"] = np.asarray(raw_phase_deg, float) * DEG
    if torque is not None:
        columns["torque"] = np.asarray(torque, float)
    if strain is not None:
        columns["shear_strain"] = np.asarray(strain, float)
    return make_run_dataset(columns, {"test": test, "specimen": specimen, "sample": sample,
                                      "run": f"{specimen}_{sample}_{test}", **attrs})


def test_raw_phase_179_deg_at_the_top_frequencies_flags_exactly_those_points():
    phase = np.full(OMEGA.size, 12.0)
    phase[-3:] = 179.0          # three highest frequencies: inertia
    phase[-4] = 89.0            # just under the 90 deg threshold: kept
    run = with_quality_flags(sweep(raw_phase_deg=phase))
    flags = run[FLAG_VARIABLE].values
    assert np.flatnonzero(flags).tolist() == [7, 8, 9]
    assert set(flags[7:]) == {INERTIA_DOMINATED}
    assert run.attrs["quality_n_inertia_dominated"] == 3
    assert "inertia_dominated" in run.attrs["quality_checks"]
    assert run[FLAG_VARIABLE].attrs["flag_meanings"].split()[0] == "inertia_dominated"


def test_without_raw_phase_the_inertia_check_is_not_testable_and_nothing_is_flagged():
    run = with_quality_flags(sweep())
    assert not run[FLAG_VARIABLE].values.any()
    assert "inertia_dominated: no raw-phase channel" in run.attrs["quality_not_testable"]
    assert "inertia_dominated" not in run.attrs["quality_checks"]


def test_torque_resolution_only_when_declared():
    torque = np.array([5e-9, 2e-8, 1e-7, 1e-6, 1e-5, 1e-5, 1e-5, 1e-5, 1e-5, 1e-5])  # N m
    undeclared = with_quality_flags(sweep(torque=torque))
    assert not undeclared[FLAG_VARIABLE].values.any()
    assert "torque_below_resolution: no torque resolution declared" in undeclared.attrs["quality_not_testable"]
    # dataset.yaml: instrument: {torque_resolution_nm: 1e-7} -> the two points below 0.1 uN m
    resolution, problem = declared_torque_resolution({"instrument": {"torque_resolution_nm": 1e-7}})
    assert (resolution, problem) == (1e-7, "")
    declared = with_quality_flags(sweep(torque=torque), torque_resolution_n_m=resolution)
    assert np.flatnonzero(declared[FLAG_VARIABLE].values & TORQUE_BELOW_RESOLUTION).tolist() == [0, 1]


@pytest.mark.parametrize("instrument, problem", [
    ("virtual Anton Paar MCR", ""),                    # a description, no resolution: not declared
    ({"model": "MCR 302"}, ""),
    ({"torque_resolution_nm": -1}, "not a positive number"),
    ({"torque_resolution_nm": "fine"}, "not a positive number"),
])
def test_declared_torque_resolution_is_never_defaulted(instrument, problem):
    value, reason = declared_torque_resolution({"material": "x", "instrument": instrument})
    assert value is None
    assert (problem in reason) if problem else reason == ""


def test_frequency_sweep_points_above_the_same_samples_lve_limit():
    # amplitude sweep of sample s1/a: G' flat at 1000 Pa up to 1 %, then 500 Pa -> limit between 1 % and 2 %
    strain_as = np.array([1e-4, 2e-4, 5e-4, 1e-3, 2e-3, 5e-3, 1e-2, 2e-2, 5e-2, 1e-1])
    amplitude = make_run_dataset({"shear_strain": strain_as, "storage_modulus": np.where(strain_as <= 1e-2, 1e3, 500.0),
                                  "loss_modulus": np.full(10, 50.0)},
                                 {"test": "amplitude_sweep", "specimen": "s1", "sample": "a", "run": "as"})
    fs_strain = np.array([0.005] * 5 + [0.03] * 5)    # the last five above any limit in (1 %, 2 %)
    same = sweep(strain=fs_strain)
    other = sweep(sample="b", strain=fs_strain)       # no amplitude sweep of its own sample
    out = {r.attrs["run"]: r for r in flag_runs([amplitude, same, other])}
    assert np.flatnonzero(out["s1_a_frequency_sweep"][FLAG_VARIABLE].values & OUTSIDE_LVE).tolist() == [5, 6, 7, 8, 9]
    assert 0.01 < out["s1_a_frequency_sweep"].attrs["quality_lve_strain"] < 0.02
    assert not out["s1_b_frequency_sweep"][FLAG_VARIABLE].values.any()
    assert "outside_lve: no amplitude sweep of the same specimen and sample" in \
        out["s1_b_frequency_sweep"].attrs["quality_not_testable"]
    assert "outside_lve" not in out["as"].attrs["quality_not_testable"]   # only frequency sweeps are checked


def test_nominal_strain_is_used_when_the_export_has_no_strain_column():
    strain_as = np.logspace(-4, -1, 10)
    amplitude = make_run_dataset({"shear_strain": strain_as, "storage_modulus": np.where(strain_as <= 1e-2, 1e3, 500.0)},
                                 {"test": "amplitude_sweep", "specimen": "s1", "sample": "a", "run": "as"})
    fs = sweep(strain_pct=5.0)  # 5 % for every point, above the limit near 1 %
    flagged = flag_runs([amplitude, fs])[1]
    assert (flagged[FLAG_VARIABLE].values == OUTSIDE_LVE).all()


def flagged_sweeps(n_inertia: int, storage_by_sample) -> list:
    """One frequency sweep per sample, raw phase 179 deg at the top ``n_inertia`` frequencies (12 deg below),
    G' set by ``storage_by_sample[sample](run)``, quality-flagged."""
    phase = np.full(OMEGA.size, 12.0)
    phase[-n_inertia:] = 179.0
    runs = []
    for sample, set_storage in storage_by_sample.items():
        run = sweep(sample=sample, raw_phase_deg=phase)
        set_storage(run["storage_modulus"].values)
        runs.append(with_quality_flags(run))
    return runs


def test_flagged_points_are_left_out_of_the_averages_unless_configured_otherwise():
    def storage(g):
        def set_storage(values):
            values[-3:] = -5e4     # what inertia does to G' at high frequency
            values[:-3] = g
        return set_storage

    runs = flagged_sweeps(3, {"a": storage(1000.0), "b": storage(1200.0)})
    excluded = average_runs(runs)
    kept = average_runs(runs, exclude_flagged=False)
    assert excluded.attrs["n_flagged_points_excluded"] == 6 and excluded.attrs["exclude_flagged"] == 1
    curve = select_average(excluded, "frequency_sweep")
    top = curve["frequency"].values.max()
    assert top == pytest.approx(OMEGA[-4] / (2 * np.pi))      # grid ends at the last unflagged frequency
    assert np.nanmin(curve["storage_modulus_mean"].values) == pytest.approx(1100.0)
    assert np.nanmin(select_average(kept, "frequency_sweep")["storage_modulus_mean"].values) < 0


def test_raw_run_figure_draws_flagged_points_hollow_with_a_legend_entry():
    def storage(g):
        def set_storage(values):
            values[:] = g * (1 + 0.1 * np.log10(OMEGA + 1))
        return set_storage

    runs = flagged_sweeps(2, {"a": storage(1000.0), "b": storage(1500.0)})
    curve = select_average(average_runs(runs), "frequency_sweep")
    ax = figure_average(curve, "storage_modulus", runs).axes[0]
    hollow = [line for line in ax.lines if line.get_marker() == "o" and line.get_markerfacecolor() == "none"
              and len(line.get_xdata())]
    assert len(hollow) == 2 and all(len(line.get_xdata()) == 2 for line in hollow)
    assert any(t.get_text() == "flagged: inertia_dominated" for t in ax.get_legend().get_texts())


def test_ingest_writes_the_flag_variable_into_every_run_file(tmp_path, repo_root):
    report = ingest_dataset(repo_root / "raw" / "agar_3pct_thesis", tmp_path / "runs", tmp_path / "report.csv")
    assert (report["status"] == "ok").all()
    for name in report["run"]:
        run = read_netcdf(tmp_path / "runs" / f"{name}.nc")
        assert run[FLAG_VARIABLE].dims == ("point",)
        assert "torque_below_resolution: no torque resolution declared" in run.attrs["quality_not_testable"]


def test_real_trios_fungi_frequency_sweep_flags_its_high_omega_points(shared_real):
    blocks = read_export(shared_real / "trios" / "hr20_fungi_frequency_sweep.xls")
    block = next(b for b in blocks if b.name == "Frequency sweep - 2")
    run = make_run_dataset({k: block.data[k].to_numpy(float) for k in block.data.columns},
                           {"test": "frequency_sweep", "specimen": "fungi", "sample": "1", "run": "fs"})
    flagged = with_quality_flags(run)
    omega = run["angular_frequency"].values
    hit = (flagged[FLAG_VARIABLE].values & INERTIA_DOMINATED) > 0
    # hand-read from the sheet (rows sorted 100 -> 0.1 rad/s): raw phase 135.100 deg at 6.30957 rad/s and above it
    # up to 179.956 deg at 100 rad/s; 48.987 deg at 5.01186 rad/s and 13-26 deg below
    assert hit.sum() == 13
    assert omega[hit].min() == pytest.approx(6.30957, rel=1e-5)
    assert omega[~hit].max() == pytest.approx(5.01186, rel=1e-5)
