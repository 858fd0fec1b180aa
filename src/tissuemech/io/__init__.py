"""Instrument export readers and dataset ingest (``dispatch.read_export``, ``ingest.ingest_dataset``).

Formats (detected from content by :func:`tissuemech.io.dispatch.detect_format`, not from the extension):
Anton Paar RheoCompass CSV/TXT (its table export too) and .xlsx (``rheocompass``), TA TRIOS text/CSV/.xls
(``trios``), TA LIMS export (``lims``), Malvern Kinexus rSpace CSV (``rspace``), documented tidy CSV (``tidy``),
plain tables whose units come from a unit row or from ``dataset.yaml`` ``columns`` (``table``). Anton Paar ``.RhPts``
object exports are recognised and refused. Every reader returns :class:`~tissuemech.io.blocks.Block` objects
(one per interval/step/action) whose ``data`` columns carry canonical names in SI units:

=====================  =======  ====================================================================
canonical name         unit     typical instrument labels (converted from)
=====================  =======  ====================================================================
``time``               s        Interval Time, Step time, Time (action)  (s, ms, min, h)
``total_time``         s        Time (RheoCompass session), Run time, Time (sequence)
``shear_strain``       1        Shear Strain, Oscillation strain, Complex shear strain  (%, 1)
``shear_stress``       Pa       Shear Stress, Stress, Oscillation stress, Complex shear stress  (Pa, kPa, MPa)
``shear_rate``         1/s      Shear Rate, Shear rate(s-¹)  (1/s, s-1, 1/min)
``viscosity``          Pa s     Viscosity  (Pa·s, mPa·s)
``complex_viscosity``  Pa s     Complex viscosity
``storage_modulus``    Pa       Storage Modulus, Shear modulus (elastic component)  (Pa, kPa, MPa)
``loss_modulus``       Pa       Loss Modulus, Shear modulus (viscous component)
``complex_modulus``    Pa       Complex modulus, Shear modulus (complex component)
``loss_factor``        1        Loss Factor, Tan(delta)
``phase_angle``        rad      Phase Shift Angle, Phase angle  (°, rad)
``raw_phase``          rad      Raw phase, Raw phase (torque)  (°)
``relaxation_modulus`` Pa       Relaxation Modulus, Modulus
``creep_compliance``   1/Pa     Creep Compliance  (1/Pa, 1/kPa, 1/MPa)
``torque``             N m      Torque, Oscillation torque  (N·m, mN·m, µN·m, nN·m, g·cm = 9.80665e-5 N·m)
``deflection_angle``   rad      Deflection Angle, Oscillation displacement, Angular displacement  (rad, mrad, µrad)
``normal_force``       N        Normal Force, Axial force  (N, mN, g = 9.80665e-3 N)
``gap``                m        Gap  (mm, µm, cm)
``temperature``        degC     Temperature  (°C, K)
``frequency``          Hz       Frequency
``angular_frequency``  rad/s    Angular frequency
``stretch``            1        tidy CSV only (uniaxial)
``nominal_stress``     Pa       tidy CSV only (P11 uniaxial, P12 simple shear)
``force``              N        tidy CSV only (indentation/uniaxial)
``displacement``       m        tidy CSV only
=====================  =======  ====================================================================

The table of names is :data:`tissuemech.canonical.CANONICAL_VARIABLES`; conversions are
:mod:`tissuemech.units`. A column is converted by its own unit: a unit with no known conversion, or of another
quantity than the column's (a modulus with no unit, a torque in s), is an error naming file, line and column,
never assumed. Errors are :class:`~tissuemech.io.errors.IngestError`; see ``docs/ingest.md`` for the formats,
their quirks and the list of bad inputs that are reported.

After ingest, :mod:`tissuemech.io.quality` adds the point-level bitmask ``quality_flags`` to every run file
(inertia-dominated raw phase, torque below a declared resolution, frequency-sweep points above the LVE limit), and
:mod:`tissuemech.io.check` (``tissuemech check raw/<name>``) validates a dataset folder without writing into it.
"""
