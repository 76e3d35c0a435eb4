"""Column layout of the flat arrays the compiled kernel works on.

The plant is lowered (like Drake's Context) into a few dense float64 arrays so that one numba call
advances everything without Python in the loop:

* ``AP[n_act, AP_N]``  actuator parameters (command chain, valve, actuator, hose, sensor, effects,
  faults); effect switches are stored as 0.0/1.0.
* ``DP[n_dof, DP_N]``  per-joint mechanical parameters (limits, end stops, damping).
* ``GP[GP_N]``         global parameters (supply, fluid, integrator settings).
* ``XS[n_act, XS_N]``  actuator state;  ``XQ[2, n_dof]`` joint positions and velocities;
  ``XG[XG_N]`` global state (time, supply node, energy ledger).

Numba freezes module-level integers at compile time, so these names cost nothing in the kernel.
"""

# --- actuator parameters -------------------------------------------------------------------------
AP_KIND = 0            # 0 cylinder, 1 rotary actuator / motor
AP_DOF = 1             # index of the driven joint in the kinematic tree
AP_U_MIN = 2           # command range (V)
AP_U_MAX = 3
AP_AMP_GAIN = 4        # amplifier transconductance (A/V)
AP_AMP_IMAX = 5        # amplifier current limit (A)
AP_SOL_TAU = 6         # solenoid current time constant (s)
AP_SPOOL_GAIN = 7      # spool position per net solenoid current (stroke fraction / A)
AP_SPOOL_WN = 8        # spool natural frequency (rad/s)
AP_SPOOL_ZETA = 9      # spool damping ratio (-)
AP_SPOOL_LIMIT = 10    # spool end stop (stroke fraction)
AP_KV = 11             # valve flow coefficient per metering edge at full opening (m^3/s/sqrt(Pa))
AP_OVERLAP = 12        # spool overlap (stroke fraction)
AP_NULL_LEAK = 13      # null leakage opening of every edge (fraction of full opening)
AP_POLY1 = 14          # opening characteristic a(s) = c1 s + c2 s^2 + c3 s^3
AP_POLY2 = 15
AP_POLY3 = 16
AP_DP_TR = 17          # laminar/turbulent transition pressure of the orifices (Pa)
AP_AREA_A = 18         # cylinder: piston area (m^2); rotary: gear ratio * displacement (m^3/rad)
AP_AREA_B = 19         # cylinder: annulus area (m^2); rotary: same as AREA_A
AP_LK_C0 = 20          # cylinder linkage: L^2 = C0 - 2 (D1 cos q + D2 sin q)  (m^2)
AP_LK_D1 = 21
AP_LK_D2 = 22
AP_LK_LMIN = 23        # pin-to-pin length at full retraction (m)
AP_STROKE = 24         # cylinder stroke (m)
AP_VDEAD_A = 25        # chamber dead volume incl. valve/manifold passages (m^3)
AP_VDEAD_B = 26
AP_VISC = 27           # viscous seal friction: N s/m (cylinder) or N m s/rad (rotary, at the joint)
AP_RELIEF_P = 28       # port relief cracking pressure (Pa)
AP_RELIEF_K = 29       # port relief conductance above cracking (m^3/s/Pa)
AP_HOSE_VOL = 30       # volume of one hose (m^3)
AP_HOSE_BETA = 31      # effective bulk modulus of oil in the hose incl. wall compliance (Pa)
AP_HOSE_I = 32         # hose fluid inertance rho*l/a (kg/m^4)
AP_HOSE_RLAM = 33      # laminar hose resistance 128 mu l/(pi d^4) (Pa s/m^3)
AP_HOSE_RTURB = 34     # turbulent hose resistance dp = R q|q| (Pa s^2/m^6)
AP_HOSE_TURB = 35      # 1.0 turbulent, 0.0 laminar
AP_SENSED = 36         # 1.0 if a potentiometer/resolver measures the joint
AP_POT_A = 37          # angle = A * raw + B  (rad/V)
AP_POT_B = 38          # (rad)
AP_POT_NOISE = 39      # sensor voltage noise, standard deviation (V)
AP_POT_LSB = 40        # ADC quantisation step (V); 0 = none
AP_POT_VMIN = 41       # ADC input range (V)
AP_POT_VMAX = 42
AP_SENS_GAIN = 43      # sensor_gain effect (-)
AP_SENS_OFFSET = 44    # sensor_offset effect (rad)
AP_E_DEADBAND = 45
AP_DB_WIDTH = 46       # (V)
AP_E_ASYM = 47
AP_ASYM_RATIO = 48     # K_v(negative) / K_v(positive)
AP_E_SPOOL_LAG = 49
AP_LAG_TAU = 50        # (s)
AP_E_DELAY = 51
AP_DELAY = 52          # (s)
AP_E_LEAK = 53
AP_LEAK_INT = 54       # cross-port leakage (m^3/s/Pa)
AP_LEAK_EXT = 55       # external leakage of each chamber to tank (m^3/s/Pa)
AP_E_COULOMB = 56
AP_COUL_TORQUE = 57    # (N m)
AP_COUL_VEL = 58       # tanh smoothing velocity (rad/s)
AP_E_BACKLASH = 59
AP_BACK_WIDTH = 60     # total play (rad)
AP_E_FLOWSAT = 61
AP_FLOWSAT_Q = 62      # (m^3/s)
AP_E_LINE = 63
AP_E_COMPLIANCE = 64
AP_COMP_K = 65         # (N m/rad)
AP_COMP_C = 66         # (N m s/rad)
AP_COMP_JA = 67        # actuator-side inertia (kg m^2)
AP_E_HYST = 68
AP_HYST_WIDTH = 69     # half width of the play operator (V)
AP_F_SPOOL_STUCK = 70  # fault: spool frozen
AP_F_SPOOL_POS = 71
AP_F_LEAK_A = 72       # fault: laminar leak of chamber A / B to tank (m^3/s/Pa)
AP_F_LEAK_B = 73
AP_F_BURST_KV = 74     # fault: hose burst, orifice to tank on line A (m^3/s/sqrt(Pa))
AP_F_SENS_MODE = 75    # fault: 0 none, 1 stuck, 2 noisy
AP_F_SENS_VALUE = 76   # stuck sensor voltage (V)
AP_F_SENS_NOISE = 77   # extra sensor noise (V)
AP_F_SENS_OFFSET = 78  # sensor voltage offset (V)
AP_CMD_H = 79          # substep the command-chain matrices below were computed for (s)
AP_PHI = 80            # 25 entries: exact discretisation of the linear command chain
AP_GAM = 105           # 10 entries
AP_N = 115

# --- per-joint mechanical parameters -------------------------------------------------------------
DP_LOWER = 0           # joint limits (rad)
DP_UPPER = 1
DP_STOP_K = 2          # end-stop stiffness (N m/rad)
DP_STOP_C = 3          # end-stop damping (N m s/rad)
DP_DAMPING = 4         # viscous joint damping (N m s/rad)
DP_ACT = 5             # index of the actuator driving the joint, -1 if passive
DP_LOCKED = 6          # 1.0: joint held rigid at its current angle, its actuator not simulated
DP_N = 7

# --- global parameters ---------------------------------------------------------------------------
GP_P_SUPPLY = 0        # pump pressure setting (Pa, gauge)
GP_P_TANK = 1          # tank / return pressure (Pa)
GP_PUMP_QMAX = 2       # pump flow limit (m^3/s), 0 = ideal pressure source
GP_PUMP_BAND = 3       # pressure-compensator regulation band (Pa)
GP_SUPPLY_C = 4        # supply line capacitance V/beta (m^3/Pa)
GP_SUPPLY_RELIEF_P = 5 # main relief cracking pressure (Pa)
GP_SUPPLY_RELIEF_K = 6 # main relief conductance (m^3/s/Pa)
GP_SUPPLY_SAG = 7      # fault: supply pressure multiplier (1 = healthy)
GP_BETA = 8            # oil bulk modulus (Pa)
GP_P_MIN = 9           # cavitation floor (Pa, gauge)
GP_P_ATM = 10          # atmospheric pressure (Pa)
GP_E_BULK = 11         # bulk_modulus effect switch
GP_BULK_SCALE = 12     # (-)
GP_BULK_PAIR = 13      # entrained-air pressure scale (Pa)
GP_ENERGY = 14         # 1.0: keep the energy ledger (costs ~10 %)
GP_H_MAX = 15          # largest integrator substep (s)
GP_RB_EVERY = 16       # refresh M(q) and bias every k substeps (0: once per output step)
GP_N = 17

# --- actuator state ------------------------------------------------------------------------------
XS_I_A = 0             # solenoid currents (A)
XS_I_B = 1
XS_SPOOL_X = 2         # spool position (stroke fraction)
XS_SPOOL_V = 3         # spool velocity (1/s)
XS_LAG_X = 4           # spool_lag filtered position
XS_P_A = 5             # chamber pressures (Pa)
XS_P_B = 6
XS_PH_A = 7            # hose valve-end node pressures (Pa), line_dynamics
XS_PH_B = 8
XS_QH_A = 9            # hose flows into the chambers (m^3/s), line_dynamics
XS_QH_B = 10
XS_TH_A = 11           # actuator-side angle and rate (joint_compliance)
XS_OM_A = 12
XS_U_HYST = 13         # hysteresis play-operator state (V)
XS_Y_BACK = 14         # backlash play-operator state (rad)
XS_U_EFF = 15          # effective command after delay/hysteresis/deadband (V), last substep
XS_Q_A = 16            # last valve flows into lines A/B (m^3/s)
XS_Q_B = 17
XS_SENS_V = 18         # last sensor voltage (V)
XS_SENS_ANGLE = 19     # last calibrated angle A*v+B (rad)
XS_CURSOR = 20         # delay-line read cursor (event count, stored as float)
XS_N = 21

# --- global state --------------------------------------------------------------------------------
XG_TIME = 0
XG_P_S = 1             # supply node pressure (Pa)
XG_E_SUPPLY = 2        # energy ledger (J): hydraulic energy delivered by the pump
XG_E_TANK = 3          # hydraulic energy returned to tank (p_T * Q)
XG_E_VALVE = 4         # dissipated in metering edges
XG_E_HOSE = 5          # dissipated in hose resistance
XG_E_LEAK = 6          # dissipated by leakage, relief and fault leaks
XG_E_MECH = 7          # dissipated by damping, friction and end-stop damping
XG_E_RELIEF_PUMP = 8   # pump-side relief and compensator spill
XG_HIST_COUNT = 9      # number of command events written to the delay line
XG_ERROR = 10          # kernel error code (0 ok): 1 NaN, 2 delay line overrun
XG_STEPS = 11          # substeps taken
XG_E_ACT = 12          # work done by the actuators on the links (hydraulic -> mechanical)
XG_E_COMPRESS = 13     # second-order term of the constant-beta continuity equation, int p^2/(2 beta) dV
XG_N = 14

# --- outputs per output step (Yact[k, a, :]) ---------------------------------------------------
YA_U = 0               # commanded voltage (V)
YA_SENS_V = 1          # sensor voltage (V)
YA_ANGLE = 2           # measured (calibrated) angle (rad)
YA_P_A = 3             # chamber pressures (Pa)
YA_P_B = 4
YA_SPOOL = 5           # spool position (stroke fraction)
YA_Q_A = 6             # valve flow into line A (m^3/s)
YA_N = 7

ERR_NAN = 1
ERR_DELAY_OVERRUN = 2
