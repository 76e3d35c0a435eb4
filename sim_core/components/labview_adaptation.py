"""LabVIEW / CompactFieldPoint adaptation: the sign of the command picks amplifier A or B."""

from numba import njit

from ..kernel.layout import AP_U_MAX, AP_U_MIN
from .base import Component, Parameter

CITATION_MARS_ND = (
    "A. Montazeri, J. Ekotuyo, 'Development of dynamic model of a 7DOF hydraulically actuated "
    "tele-operated robot for decommissioning applications', American Control Conference, 2016"
)


class LabviewAdaptation(Component):
    """LabVIEW/cFP adaptation module: signed command voltage -> two unipolar amplifier inputs.

    The operator's VI produces one signed output ``Lab_out``; an IF block routes it to amplifier A
    when positive and to amplifier B when negative (Montazeri & Ekotuyo, Sec. III):

        v_A = max(u, 0),   v_B = max(-u, 0),   u in [u_min, u_max]

    The cFP channel names say which analog outputs (one per amplifier) and which analog input (the
    potentiometer) a LabVIEW VI would address for this joint.
    """

    section = "cfp"
    citation = CITATION_MARS_ND
    PARAMETERS = (
        Parameter("command_range", "V", "allowed command voltage [min, max]", (-10.0, 10.0), kind="vec", length=2),
        Parameter("output_a", "-", "cFP analog output channel driving amplifier A (e.g. 'cFP1/AO0')", "", kind="str"),
        Parameter("output_b", "-", "cFP analog output channel driving amplifier B", "", kind="str"),
        Parameter("input", "-", "cFP analog input channel of the joint's potentiometer ('' if none)", "", kind="str"),
    )

    def __init__(self, values=None, where=""):
        super().__init__(values, where)
        lo, hi = self.values["command_range"]
        if not lo < 0.0 < hi:
            from .base import ParameterError

            raise ParameterError(f"{self.where}.command_range: must contain 0 V (the valve's null: a positive command "
                                 f"opens it one way, a negative one the other), got {[lo, hi]}; a unipolar output nulled "
                                 f"mid-range (0 .. 10 V, null at 5 V) keeps [-10, 10] and its record is read with "
                                 f"--column u_<joint>=SOURCE:*2-10")

    def lower(self, lw, a, spec, js):
        lw.AP[a, AP_U_MIN], lw.AP[a, AP_U_MAX] = self["command_range"]


@njit(inline="always")
def adapt(u):
    """Signed command (V) -> (v_A, v_B) unipolar amplifier inputs (V)."""
    if u >= 0.0:
        return u, 0.0
    return 0.0, -u
