"""Pressure supply: pump with pressure compensator, main relief and tank."""

from numba import njit

from ..kernel.layout import GP, XG, XG_E_RELIEF_PUMP, XG_E_SUPPLY, XG_E_TANK, col
from .base import Component, Parameter

P_SUPPLY, P_TANK, PUMP_QMAX, PUMP_BAND, SUPPLY_C, SUPPLY_RELIEF_P, SUPPLY_RELIEF_K, SUPPLY_SAG = GP.declare(
    "supply",
    col("P_SUPPLY", "Pa", "pump pressure setting (gauge)"),
    col("P_TANK", "Pa", "tank / return pressure"),
    col("PUMP_QMAX", "m^3/s", "pump flow limit, 0 = ideal pressure source"),
    col("PUMP_BAND", "Pa", "pressure-compensator regulation band"),
    col("SUPPLY_C", "m^3/Pa", "supply line capacitance V/beta"),
    col("SUPPLY_RELIEF_P", "Pa", "main relief cracking pressure"),
    col("SUPPLY_RELIEF_K", "m^3/s/Pa", "main relief conductance"),
    col("SUPPLY_SAG", "-", "fault: supply pressure multiplier (1 = healthy)"),
)
P_S = XG.declare("supply", col("P_S", "Pa", "supply node pressure", ode=True, atol=1e-2))


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
    FAULTS = ("supply_sag",)

    def lower_global(self, lw, spec):
        GP_ = lw.GP
        GP_[P_SUPPLY] = self["pressure"]
        GP_[P_TANK] = self["tank_pressure"]
        GP_[PUMP_QMAX] = self["max_flow"]
        GP_[PUMP_BAND] = self["compensator_band"]
        GP_[SUPPLY_C] = self["line_volume"] / spec.fluid["bulk_modulus"]
        GP_[SUPPLY_RELIEF_P] = self["relief_pressure"]
        GP_[SUPPLY_RELIEF_K] = self["relief_conductance"]
        GP_[SUPPLY_SAG] = 1.0

    @staticmethod
    def lower_fault(lw, a, kind, mode):
        lw.GP[SUPPLY_SAG] = float(mode.get("factor", 0.7))


@njit(inline="always")
def pump_flow(p_s, GP):
    """Compensated pump flow (m^3/s) and its slope: full below p_set - band, none at p_set."""
    qmax = GP[PUMP_QMAX]
    band = GP[PUMP_BAND]
    xr = (GP[P_SUPPLY] * GP[SUPPLY_SAG] - p_s) / band
    if xr >= 1.0:
        return qmax, 0.0
    if xr <= 0.0:
        return 0.0, 0.0
    return qmax * xr, -qmax / band


@njit(inline="always")
def main_relief(p_s, GP):
    """Main relief flow (m^3/s) and its slope."""
    if p_s > GP[SUPPLY_RELIEF_P]:
        return GP[SUPPLY_RELIEF_K] * (p_s - GP[SUPPLY_RELIEF_P]), GP[SUPPLY_RELIEF_K]
    return 0.0, 0.0


@njit(inline="always")
def supply_node(h, q_supply, dq_supply, GP, XG, energy):
    """Advance the supply pressure one substep given the valves' draw ``q_supply`` and its slope
    with respect to the supply pressure (linearly implicit); an ideal source just holds p_set."""
    p_t = GP[P_TANK]
    if GP[PUMP_QMAX] > 0.0:
        p_s = XG[P_S]
        qp, dqp = pump_flow(p_s, GP)
        qr, dqr = main_relief(p_s, GP)
        p_s_n = p_s + h * (qp - q_supply - qr) / (GP[SUPPLY_C] - h * (dqp - dq_supply - dqr))
        if energy:
            dps = p_s_n - p_s
            psm = 0.5 * (p_s + p_s_n)
            qp_e = qp + dqp * dps
            qr_e = qr + dqr * dps
            XG[XG_E_SUPPLY] += h * qp_e * psm      # energy delivered by the pump
            XG[XG_E_RELIEF_PUMP] += h * qr_e * (psm - p_t)
            XG[XG_E_TANK] += h * p_t * qr_e
        if p_s_n < p_t:
            p_s_n = p_t
        XG[P_S] = p_s_n
    else:
        XG[P_S] = GP[P_SUPPLY] * GP[SUPPLY_SAG]


@njit(inline="always")
def supply_pressure(y_ps, GP):
    """Reference solver: the supply pressure, from its state when the pump is flow limited."""
    if GP[PUMP_QMAX] > 0.0:
        return y_ps
    return GP[P_SUPPLY] * GP[SUPPLY_SAG]


@njit(inline="always")
def supply_derivative(p_s, q_supply, GP):
    """Reference solver: dp_s/dt of a flow-limited supply (0 for an ideal source)."""
    if GP[PUMP_QMAX] > 0.0:
        xr = (GP[P_SUPPLY] * GP[SUPPLY_SAG] - p_s) / GP[PUMP_BAND]
        qp = GP[PUMP_QMAX] * min(max(xr, 0.0), 1.0)
        qr = GP[SUPPLY_RELIEF_K] * (p_s - GP[SUPPLY_RELIEF_P]) if p_s > GP[SUPPLY_RELIEF_P] else 0.0
        return (qp - q_supply - qr) / GP[SUPPLY_C]
    return 0.0
