"""Pressure supply: pump with pressure compensator, main relief and tank."""

from .base import Component, Parameter


class Pump(Component):
    """Pump as a pressure source, ideal or flow-limited, with a main relief valve.

    Ideal (``max_flow = 0``): p_s = p_set (Papadopoulos et al., Sec. III-a: pressure-compensated
    piston pumps as ideal sources; Montazeri & Ekotuyo: 'ideal pressure source').

    Flow-limited: a supply node with line capacitance C_s = V_s / beta,

        C_s dp_s/dt = Q_pump(p_s) - sum Q_valves - Q_relief(p_s)
        Q_pump = Q_max clip((p_set - p_s) / band, 0, 1)   (compensator destrokes between p_set - band and p_set)
        Q_relief = K_r max(p_s - p_relief, 0)

    so valves that together ask for more than ``max_flow`` pull the supply down (the MARS-ND arms
    share one Brokk pump). Tank (return) pressure is constant.
    """

    section = "supply"
    citation = (
        "E. Papadopoulos et al., IEEE/ASME T-Mech 8(2), 2003, Sec. III-a; N. D. Manring, "
        "Hydraulic Control Systems, Wiley, 2005, ch. 6"
    )
    PARAMETERS = (
        Parameter("pressure", "Pa", "pump pressure setting (gauge)", None, 1e5, 6e7),
        Parameter("tank_pressure", "Pa", "return line pressure (gauge)", 0.0, 0.0, 2e6),
        Parameter("max_flow", "m^3/s", "pump flow limit; 0 = ideal pressure source", 0.0, 0.0, 0.1),
        Parameter("compensator_band", "Pa", "pressure range over which the compensator destrokes", 5e5, 1e4, 1e7),
        Parameter("line_volume", "m^3", "oil volume between pump and valves (supply node capacitance)", 1e-3, 1e-5, 1.0),
        Parameter("relief_pressure", "Pa", "main relief cracking pressure", None, 1e5, 8e7),
        Parameter("relief_conductance", "m^3/s/Pa", "main relief flow per Pa above cracking", 1e-9, 1e-13, 1e-5),
    )
