"""The links' mass properties as a whole: one factor on the URDF's masses and inertias."""

from .base import Component, Parameter


class LinkMasses(Component):
    """A factor on every link's mass and rotational inertia (centres of mass unchanged).

    The URDF's masses come from CAD or a scale and are often off by 10-20 % once hoses, bolts and
    paint are on; scaling them all is the nominal model's correction for that (``links.mass_scale``),
    a different thing from a point mass carried at one link's payload point (the ``payload`` effect):
    gravity and inertia grow about every joint in proportion to the mass already there.
    """

    section = "links"
    citation = "URDF <inertial> (mass, inertia); a uniform scale, as a calibration parameter"
    PARAMETERS = (
        Parameter("mass_scale", "-", "factor on every link's mass and inertia (1 = the URDF's)", 1.0, 0.2, 5.0),
    )

    def lower_masses(self, lw) -> None:
        """Scale the lowered links' masses and inertias in place."""
        s = self.values["mass_scale"]
        if s != 1.0:
            lw.mass *= s
            lw.inertia *= s
