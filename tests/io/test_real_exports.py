"""Every real rheometer export in shared/data/real through read_export: one point per file, read by hand.

Each case quotes the raw line (or spreadsheet row) the expected values were read from, and checks the unit
conversion of that column (g·cm -> N·m, mN·m / µN·m -> N·m, min -> s, % -> 1, kPa / 1/MPa -> Pa / 1/Pa,
° -> rad, mm / µm -> m). Skips when the shared folder is absent.
"""
from __future__ import annotations

import numpy as np
import pytest

from tissuemech.io.dispatch import detect_format, read_export

GF_CM = 9.80665e-5  # N m per gram-force centimetre


def block_named(blocks, name):
    matches = [b for b in blocks if b.name == name]
    assert len(matches) == 1, [b.name for b in blocks]
    return matches[0]


def point_at_line(block, line: int) -> dict:
    """Canonical values of the data row at 1-based ``line``, for blocks whose data lines are consecutive
    (the readers keep the line of the first point only)."""
    return block.data.iloc[line - block.meta["first_data_line"]].to_dict()


# --- Anton Paar RheoCompass, CNF hydrogel (10 replicate stress relaxations, UTF-16, decimal comma) --------
# Column row:  Point No.  Time  Shear Strain  Shear Stress  Relaxation Modulus  Torque  Temperature  Status
# Unit row:              [s]   [%]           [Pa]          [Pa]                [mN·m]  [°C]
# Each case: the raw line 57 (point 51), as "point, time, strain %, stress Pa, G Pa, torque mN·m, T °C".
CNF_LINE_57 = {
    "HC1_stressrelaxation_20C_2.csv": "51\t0,817\t0,1\t0,11976\t119,8\t0,00054996\t20,00\tDy_auto",
    "HC1_stressrelaxation_20C_3.csv": "51\t0,817\t0,1\t0,033158\t33,133\t0,00015226\t20,00\tDy_auto",
    "HC1_stressrelaxation_20C_5.csv": "51\t0,817\t0,1\t0,013824\t13,813\t6,3479E-05\t20,00\tDy_auto",
    "HC1_stressrelaxation_20C_6.csv": "51\t0,817\t0,1\t0,037732\t37,712\t0,00017327\t20,00\tDy_auto",
    "HC1_stressrelaxation_20C_7.csv": "51\t0,817\t0,1\t0,04138\t41,348\t0,00019002\t20,00\tDy_auto",
    "HC1_stressrelaxation_20C_8.csv": "51\t0,817\t0,1\t0,076784\t76,786\t0,0003526\t20,00\tDy_auto",
    "HC1_stressrelaxation_20C_9.csv": "51\t0,817\t0,0999\t0,19844\t198,72\t0,00091125\t20,00\tDy_auto",
    "HC1_stressrelaxation_20C_10.csv": "51\t0,817\t0,1\t0,19957\t199,65\t0,00091644\t20,00\tDy_auto",
    "HC1_stressrelaxation_20C_11.csv": "51\t0,817\t0,0999\t0,065862\t65,908\t0,00030244\t20,00\tDy_auto",
    "HC1_stressrelaxation_20C_12.csv": "51\t0,817\t0,1\t0,17525\t175,29\t0,00080477\t20,00\tDy_auto",
}
# the same values, read by eye from the lines above (not parsed from them)
CNF_EXPECTED = {  # strain %, stress Pa, G Pa, torque mN·m
    "HC1_stressrelaxation_20C_2.csv": (0.1, 0.11976, 119.8, 0.00054996),
    "HC1_stressrelaxation_20C_3.csv": (0.1, 0.033158, 33.133, 0.00015226),
    "HC1_stressrelaxation_20C_5.csv": (0.1, 0.013824, 13.813, 6.3479e-05),
    "HC1_stressrelaxation_20C_6.csv": (0.1, 0.037732, 37.712, 0.00017327),
    "HC1_stressrelaxation_20C_7.csv": (0.1, 0.04138, 41.348, 0.00019002),
    "HC1_stressrelaxation_20C_8.csv": (0.1, 0.076784, 76.786, 0.0003526),
    "HC1_stressrelaxation_20C_9.csv": (0.0999, 0.19844, 198.72, 0.00091125),
    "HC1_stressrelaxation_20C_10.csv": (0.1, 0.19957, 199.65, 0.00091644),
    "HC1_stressrelaxation_20C_11.csv": (0.0999, 0.065862, 65.908, 0.00030244),
    "HC1_stressrelaxation_20C_12.csv": (0.1, 0.17525, 175.29, 0.00080477),
}


@pytest.mark.parametrize("name", sorted(CNF_EXPECTED))
def test_rheocompass_cnf_hydrogel_point_51(shared_real, name):
    path = shared_real / "rheocompass_cnf_hydrogel" / name
    raw = path.read_bytes().decode("utf-16").splitlines()[56]
    assert raw == CNF_LINE_57[name]  # the line the values were read from
    (block,) = read_export(path)
    assert block.name == "Step strain / 1" and block.meta["first_data_line"] == 7
    p = point_at_line(block, 57)
    strain_pct, stress, modulus, torque_mnm = CNF_EXPECTED[name]
    assert p["time"] == pytest.approx(0.817)
    assert p["shear_strain"] == pytest.approx(strain_pct / 100)         # % -> 1
    assert p["shear_stress"] == pytest.approx(stress)
    assert p["relaxation_modulus"] == pytest.approx(modulus)
    assert p["torque"] == pytest.approx(torque_mnm * 1e-3)               # mN·m -> N·m
    assert p["temperature"] == pytest.approx(20.0)


def test_rheocompass_french_multi_result_flow_curve(shared_real):
    path = shared_real / "rheocompass_misc" / "flowcurve_laos_oscillation_fr.csv"
    blocks = read_export(path)
    # Intervalle et points de données: 1 60, then on line 11 (Point No. 1):
    # "\t1\t1\t1\t73,196\t300\t\t2,21E+04\t\t\t21,00\t2,3981\t0,05\tDy_auto\t\t"
    # columns: Point No., Temps [s], Intervalle Temps [s], Contrainte [Pa], Gradient [1/s], Fréquence [Hz],
    # Déformation [%], G' [Pa], G'' [Pa], Température [°C], Couple [mN·m], Force Normale [N]
    line = path.read_bytes().decode("utf-16").splitlines()[10]
    assert line == "\t1\t1\t1\t73,196\t300\t\t2,21E+04\t\t\t21,00\t2,3981\t0,05\tDy_auto\t\t"
    block = block_named(blocks, "Flow Curve 1 / 1")
    assert block.meta["first_data_line"] == 11
    p = block.data.iloc[0]
    assert p["shear_stress"] == pytest.approx(73.196)
    assert p["shear_rate"] == pytest.approx(300.0)
    assert p["shear_strain"] == pytest.approx(221.0)                    # 2,21E+04 % -> 221
    assert p["torque"] == pytest.approx(2.3981e-3)                       # mN·m -> N·m
    assert p["normal_force"] == pytest.approx(0.05)
    assert p["time"] == pytest.approx(1.0) and p["total_time"] == pytest.approx(1.0)
    # "Oscillations 1 / 2" (30 points all flagged invalid) is no block; 1 / 3 keeps its 16 valid points of 23
    assert "Oscillations 1 / 2" not in [b.name for b in blocks]
    osc = block_named(blocks, "Oscillations 1 / 3")
    assert len(osc.data) == 16 and osc.meta["invalid_points"] == 7


def test_rheocompass_sponge_frequency_sweep_drops_waveforms(shared_real):
    path = shared_real / "rheocompass_misc" / "sponge_freqsweep_waveforms_en.csv"
    # line 11 (Point No. 1; the point row also carries the first waveform sample in the "Waveform" columns):
    # "\t1\t0\t6.985\t-1.6586E-05\t4.797E-06\t0.66\t3.000\t5\t0.101\t719.5\t7.1514E+05\t32771\t1.3954E-06\t..."
    # columns: Point No., Period Time [s] (Waveform), Average Time [s], Deflection Angle [rad] (Waveform),
    # Torque [N·m] (Waveform), Normal Force [N], Gap [mm], Frequency [Hz], Shear Strain [%], Shear Stress [Pa],
    # Storage Modulus [Pa], Loss Modulus [Pa], ...
    (block,) = read_export(path)
    assert block.meta["first_data_line"] == 11
    assert len(block.data) == 12                                          # 12 points, ~6000 waveform rows dropped
    p = block.data.iloc[0]
    assert p["time"] == pytest.approx(6.985)
    assert p["gap"] == pytest.approx(3.000e-3)                           # mm -> m
    assert p["frequency"] == pytest.approx(5.0)
    assert p["shear_strain"] == pytest.approx(0.101e-2)                  # % -> 1 (point value, not the waveform)
    assert p["shear_stress"] == pytest.approx(719.5)
    assert p["storage_modulus"] == pytest.approx(7.1514e5)
    assert p["loss_modulus"] == pytest.approx(32771.0)
    assert "torque" not in block.data and "deflection_angle" not in block.data  # waveform-only columns


# --- TA TRIOS ------------------------------------------------------------------------------------------------
def test_trios_text_carbopol_stress_relaxation(shared_real):
    path = shared_real / "trios" / "arg2_carbopol_multistep.txt"
    # lines 1375-1379:
    # "Stress relaxation - 7" / "Torque\tDisplacement\tStep time\tTemperature\tAxial force\tGap"
    # "µN.m\trad\ts\t°C\tN\tmm" / "-183.214\t0.00000\t0.00000\t32768.00\t-0.367599\t1.50000"
    # "3323.10\t1.25336e-6\t5.44000e-4\t32768.00\t-0.367599\t1.50000"   <- line 1379, asserted
    assert detect_format(path) == "trios_text"
    blocks = read_export(path)
    assert len(blocks) == 22
    block = block_named(blocks, "Stress relaxation - 7")
    assert block.index == 7 and block.meta["first_data_line"] == 1378
    p = point_at_line(block, 1379)
    assert p["torque"] == pytest.approx(3323.10e-6)                       # µN.m -> N·m
    assert p["deflection_angle"] == pytest.approx(1.25336e-6)
    assert p["time"] == pytest.approx(5.44e-4)
    assert p["gap"] == pytest.approx(1.5e-3)                               # mm -> m
    assert p["normal_force"] == pytest.approx(-0.367599)


def test_trios_csv_step_time_in_minutes(shared_real):
    path = shared_real / "trios" / "hr30_multistep_minutes.csv"
    # lines 124-127: "Peak hold - 1" / "Stress,Shear rate,Viscosity,Step time,Temperature,Normal stress"
    # "Pa,1/s,Pa.s,min,°C,Pa" / "47.86,161.863,0.296,0.0168667,20.00,38.26"   <- line 127
    blocks = read_export(path)
    block = block_named(blocks, "Peak hold - 1")
    assert block.meta["first_data_line"] == 127 and block.meta["labels"]["time"] == "min"
    p = block.data.iloc[0]
    assert p["time"] == pytest.approx(0.0168667 * 60)                      # min -> s (1.012 s)
    assert p["shear_stress"] == pytest.approx(47.86)
    assert p["shear_rate"] == pytest.approx(161.863)
    assert p["viscosity"] == pytest.approx(0.296)
    # [Geometry Parameters] "Diameter,40.0 mm" and "Gap,1000 µm": value and unit in one cell
    assert block.meta["radius_m"] == pytest.approx(20e-3) and block.meta["gap_m"] == pytest.approx(1e-3)


def test_trios_xls_hs60_flow_sweep(shared_real):
    path = shared_real / "trios" / "arg2_hs60_las.xls"
    # sheet "Flow sweep - 4" (Sheet1/Sheet2 are empty): row 2 names, row 3 units "Pa, 1/s, Pa.s, s, °C, Pa",
    # row 4: [303.671, 1000.01, 0.303668, 9.99849, 20.0, 0.86885]
    (block,) = read_export(path)
    assert block.name == "Flow sweep - 4" and block.meta["first_data_line"] == 4
    p = block.data.iloc[0]
    assert p["shear_stress"] == pytest.approx(303.671)
    assert p["shear_rate"] == pytest.approx(1000.01)
    assert p["viscosity"] == pytest.approx(0.303668)                      # Pa.s
    assert p["time"] == pytest.approx(9.99849)
    assert p["shear_stress"] / p["shear_rate"] == pytest.approx(p["viscosity"], rel=1e-4)


def test_trios_xls_fungi_amplitude_sweep(shared_real):
    path = shared_real / "trios" / "hr20_fungi_amplitude_sweep.xls"
    # sheet "Amplitude sweep - 2", units row: Pa, Pa, (none), rad/s, µN.m, s, °C, °, rad, %
    # row 4: [17585.4, 3266.29, 0.185739, 3.14159, 0.138538, 4.98502, 25.0, 13.7617, 0.000192694, 0.0100365]
    # sheet "Axial - 1", units s, °C, Pa, N, µm; row 4: [0.13709, 25.0, 521.165, 0.0130983, 8520.59]
    axial, sweep = read_export(path)
    assert sweep.name == "Amplitude sweep - 2"
    p = sweep.data.iloc[0]
    assert p["storage_modulus"] == pytest.approx(17585.4) and p["loss_modulus"] == pytest.approx(3266.29)
    assert p["torque"] == pytest.approx(0.138538e-6)                      # µN.m -> N·m
    assert p["shear_strain"] == pytest.approx(0.0100365e-2)               # % -> 1
    assert p["raw_phase"] == pytest.approx(np.deg2rad(13.7617))           # ° -> rad
    assert axial.name == "Axial - 1"
    assert axial.data.iloc[0]["gap"] == pytest.approx(8520.59e-6)         # µm -> m
    assert axial.data.iloc[0]["normal_force"] == pytest.approx(0.0130983)


def test_trios_xls_fungi_frequency_sweep_raw_phase_near_180(shared_real):
    path = shared_real / "trios" / "hr20_fungi_frequency_sweep.xls"
    # sheet "Frequency sweep - 2", row 4:
    # [37048.8, 3676.21, 0.0992262, 100.0, 9525.65, 6.07309, 25.0, 179.956, 0.0425865, 372.307]
    # (G' Pa, G'' Pa, tan δ, ω rad/s, torque µN.m, step time s, T °C, raw phase °, displacement rad, |η*| Pa.s)
    axial, sweep = read_export(path)
    p = sweep.data.iloc[0]
    assert p["angular_frequency"] == pytest.approx(100.0)
    assert p["torque"] == pytest.approx(9525.65e-6)                       # µN.m -> N·m
    assert p["raw_phase"] == pytest.approx(np.deg2rad(179.956))           # the inertia quirk is kept as read
    assert p["complex_viscosity"] == pytest.approx(372.307)
    assert axial.data.iloc[0]["gap"] == pytest.approx(9444.6e-6)          # µm -> m


# --- TA LIMS (ARES-G2) ---------------------------------------------------------------------------------------
def test_ta_lims_ares_g2_tts(shared_real):
    path = shared_real / "ta_lims" / "ares_g2_frequency_sweep_tts.txt"
    # `file` calls it "Windows setup INFormation"; it also holds [Step] and "Instrument name" (TRIOS markers)
    assert detect_format(path) == "lims"
    blocks = read_export(path)
    assert [b.name for b in blocks][:2] == ["Frequency sweep (150.0 °C)", "Frequency sweep (140.0 °C)"]
    assert len(blocks) == 20 and all(len(b.data) == 17 for b in blocks)
    # line 106, first "Data point" of step 1; the cells read by hand (variable [unit] = value):
    # Oscillation torque [g.cm] = 0.108450026649023, Oscillation strain [%] = 1.00105442106724,
    # Step time [s] = 20.0053482055664, Gap [mm] = 1.02824240457267, Phase angle [°] = 18.1133201694153,
    # Storage modulus [Pa] = 10044.287109375, Loss modulus [Pa] = 3285.56372070313, Complex modulus [Pa] = 10568,
    # Storage compliance [1/MPa] = 89.935987489298, G*.sin(delta) [kPa] = 3.28556372070312
    first = blocks[0]
    assert first.meta["first_data_line"] == 106
    p = first.data.iloc[0]
    assert p["torque"] == pytest.approx(0.108450026649023 * GF_CM)        # g·cm -> N·m (1.0635e-5)
    assert p["shear_strain"] == pytest.approx(1.00105442106724e-2)        # % -> 1
    assert p["time"] == pytest.approx(20.0053482055664)
    assert p["gap"] == pytest.approx(1.02824240457267e-3)                 # mm -> m
    assert p["phase_angle"] == pytest.approx(np.deg2rad(18.1133201694153))
    assert p["storage_modulus"] == pytest.approx(10044.287109375)
    assert p["temperature"] == pytest.approx(149.977996826172)
    aux = first.meta["auxiliary"].iloc[0]
    assert aux["Storage compliance"] == pytest.approx(89.935987489298e-6)  # 1/MPa -> 1/Pa
    assert aux["G*.sin(delta)"] == pytest.approx(3285.56372070312)         # kPa -> Pa
    # the converted redundant columns agree with the moduli: J' = G'/|G*|^2, G*.sin(delta) = G''
    assert aux["Storage compliance"] == pytest.approx(p["storage_modulus"] / p["complex_modulus"] ** 2, rel=1e-3)
    assert aux["G*.sin(delta)"] == pytest.approx(p["loss_modulus"], rel=1e-6)
    # line 524, first point of the last step "Frequency sweep (-40.0 °C)":
    # Oscillation torque [g.cm] = 22.9947733206743, Storage modulus [Pa] = 260040528, Temperature = -40.0029983520508
    last = blocks[-1]
    assert last.name == "Frequency sweep (-40.0 °C)" and last.meta["first_data_line"] == 524
    assert last.data.iloc[0]["torque"] == pytest.approx(22.9947733206743 * GF_CM)
    assert last.data.iloc[0]["storage_modulus"] == pytest.approx(260040528.0)
    assert last.data.iloc[0]["temperature"] == pytest.approx(-40.0029983520508)
    # the anonymised geometry ("Diameter 0.0 mm") is left unknown rather than taken as a zero radius
    assert "radius_m" not in first.meta


# --- Malvern Kinexus rSpace ----------------------------------------------------------------------------------
def test_malvern_kinexus_multistep(shared_real):
    path = shared_real / "malvern" / "kinexus_multistep.csv"
    lines = path.read_text(encoding="utf-8").splitlines()
    assert detect_format(path) == "rspace"
    blocks = read_export(path)
    assert len(blocks) == 17
    # line 2: "Pre Shear Initial;112,3;1,000;30,54;47,57;4,75275E+003;0,2044;;;;;;;1,284E-003;4,516;20,93;9,1500"
    assert lines[1] == ("Pre Shear Initial;112,3;1,000;30,54;47,57;4,75275E+003;0,2044;;;;;;;1,284E-003;4,516;"
                        "20,93;9,1500")
    pre = blocks[0]
    assert pre.name == "Pre Shear Initial" and len(pre.data) == 300
    p = pre.data.iloc[0]
    assert p["total_time"] == pytest.approx(112.3) and p["time"] == pytest.approx(1.0)
    assert p["shear_stress"] == pytest.approx(30.54)
    assert p["shear_rate"] == pytest.approx(47.57)                        # "Shear rate(s-¹)"
    assert p["shear_strain"] == pytest.approx(47.5275)                    # 4,75275E+003 % -> 1
    assert p["torque"] == pytest.approx(1.284e-3)                          # "Torque(N m)"
    assert p["gap"] == pytest.approx(9.15e-3)                              # mm -> m
    assert p["temperature"] == pytest.approx(20.93)
    # line 468: "Oscillation Frequency Table;1,472E+003;400,0;;;;0,1982;0,763941;0,01000;1,000;130,1;14,59;130,9;
    #            4,205E-005;7,259E-004;21,00;9,1500"
    osc = block_named(blocks, "Oscillation Frequency Table")
    assert osc.meta["first_data_line"] == 468
    q = osc.data.iloc[0]
    assert q["shear_strain"] == pytest.approx(0.763941e-2)                # complex shear strain, % -> 1
    assert q["shear_stress"] == pytest.approx(1.0)                        # complex shear stress amplitude
    assert q["frequency"] == pytest.approx(0.01)
    assert q["storage_modulus"] == pytest.approx(130.1) and q["loss_modulus"] == pytest.approx(14.59)
    assert q["complex_modulus"] == pytest.approx(q["shear_stress"] / q["shear_strain"], rel=2e-3)
    # line 882, first processed point after 213 raw waveform rows:
    # "Oscillation Single Frequency;3,997E+003;4,031;;;;0,1810;0,370528;0,2500;0,5004;134,3;13,72;135,0;..."
    single = block_named(blocks, "Oscillation Single Frequency")
    assert single.meta["waveform_rows"] == 213 and len(single.data) == 5
    assert single.meta["first_data_line"] == 882
    assert single.data.iloc[0]["time"] == pytest.approx(4.031)
    assert single.data.iloc[0]["storage_modulus"] == pytest.approx(134.3)
    assert single.data.iloc[0]["frequency"] == pytest.approx(0.25)


def test_ingest_stage_on_real_lims_and_kinexus(shared_real, tmp_path):
    """The ingest stage reads the real exports in place (source_dir) into canonical runs, block by name/index."""
    import pandas as pd

    from tissuemech.canonical import read_netcdf
    from tissuemech.io.ingest import ingest_dataset

    dataset = tmp_path / "raw" / "real_mix"
    dataset.mkdir(parents=True)
    (dataset / "dataset.yaml").write_text(f"material: mixed\nlicense: see shared README\ncitation: n/a\n"
                                          f"source_dir: {shared_real}\n")
    pd.DataFrame([
        {"file": "ta_lims/ares_g2_frequency_sweep_tts.txt", "specimen": "p", "sample": "1", "test": "frequency_sweep",
         "order": 1, "block": "Frequency sweep (150.0 °C)"},
        {"file": "malvern/kinexus_multistep.csv", "specimen": "k", "sample": "1", "test": "flow_curve", "order": 1,
         "block": "4"},
    ]).to_csv(dataset / "samples.csv", index=False)
    out = tmp_path / "results"
    report = ingest_dataset(dataset, out / "runs", out / "ingest_report.csv")
    assert list(report["status"]) == ["ok", "ok"], list(report["reason"])
    lims = read_netcdf(out / "runs" / f"{report['run'][0]}.nc")
    assert lims.attrs["format"] == "ta_lims" and lims.sizes["point"] == 17
    assert float(lims["torque"][0]) == pytest.approx(0.108450026649023 * GF_CM)
    flow = read_netcdf(out / "runs" / f"{report['run'][1]}.nc")
    # "Flow Curve Down;496,3;5,000;110,7;500,0;2,46236E+005;0,2234;;;;;;;4,656E-003;234,0;21,00;9,1500" (line 352)
    assert flow.attrs["block"] == "Flow Curve Down" and flow.sizes["point"] == 58
    assert float(flow["shear_stress"][0]) == pytest.approx(110.7) and float(flow["shear_rate"][0]) == 500.0
    assert float(flow["shear_strain"][0]) == pytest.approx(2462.36)
